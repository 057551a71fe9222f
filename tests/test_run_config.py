"""Issue 11: a recording describes itself; `--set` overrides validated like the file.

The run's fully resolved configuration is MCAP metadata ("swarmhil.config"), the validated scenario
document an attachment, and summary.json["config"] the same. Every report and the replay then work
from the run directory alone: the test deletes the scenario file (a name not in deploy/scenarios,
with a camera unlike the default) and strips "config" from summary.json, and checks the reports used
the recorded camera.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from conftest import ROOT, read_mcap
from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

CLI = [sys.executable, "-m", "swarmhil.deploy.cli"]

SCENARIO = """
[run]
name = "selfdescribing"
duration_s = 200.0
step_s = 10.0
seed = 3

[camera]
detection_range_m = 777.0
image_px = 960
focal_px = 1234.0

[controller]
name = "sabatini"

[sensing]
kind = "scene"

[nav]
imaging = "exact"
navigator = "rough"

[dispersion]
count = 4
sigma_roe_m = [20.0, 40.0, 15.0, 15.0, 15.0, 15.0]
along_track_spacing_m = 120.0

[link]
range_m = 600.0

[beacon]
period_s = 20.0
"""


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, cwd=cwd or ROOT, timeout=600)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("selfdesc")
    scen = d / "selfdescribing-unique.toml"
    scen.write_text(SCENARIO)
    out = d / "run"
    r = _cli("run", str(scen), "--in-process", "--out", str(out), "--set", "run.duration_s=150",
             "--set", "controller.params.k_ecc=1.5")
    assert r.returncode == 0, r.stderr
    scen.unlink()  # from here on, only the run directory exists
    return out


def test_the_recording_carries_the_resolved_configuration_and_the_document(recorded: Path) -> None:
    with open(recorded / "run.mcap", "rb") as f:
        reader = make_reader(f)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        atts = {a.name: a for a in reader.iter_attachments()}
    cfg = json.loads(meta["swarmhil.config"]["json"])
    assert meta["swarmhil.run"]["scenario_file"] == "selfdescribing-unique.toml"
    assert cfg["sets"] == ["run.duration_s=150", "controller.params.k_ecc=1.5"]
    assert cfg["run"]["duration_s"] == 150.0 and cfg["run"]["steps"] == 15 and cfg["run"]["seed"] == 3
    assert cfg["controller"]["params"]["k_ecc"] == 1.5
    assert cfg["camera"] == {"detection_range_m": 777.0, "image_px": 960, "focal_px": 1234.0}
    assert cfg["link"]["range_m"] == 600.0 and cfg["link"]["loss_probability"] == 0.0  # defaults filled in
    assert cfg["supervision"] == {"stall_timeout_s": 120.0, "restart": "never", "max_restarts": 3}
    assert [s["id"] for s in cfg["spacecraft"]] == ["sc01", "sc02", "sc03", "sc04"]
    assert all(len(s["roe_m"]) == 6 for s in cfg["spacecraft"])
    assert cfg["software_version"]
    doc = json.loads(atts["scenario.json"].data)
    assert doc["doc"]["run"]["duration_s"] == 150 and doc["doc"]["camera"]["focal_px"] == 1234.0
    summary = json.loads((recorded / "summary.json").read_text())
    assert summary["config"] == cfg


def test_every_report_and_the_replay_work_from_the_recording_alone(recorded: Path, tmp_path: Path) -> None:
    s = json.loads((recorded / "summary.json").read_text())
    del s["config"]  # the MCAP alone must do
    (recorded / "summary.json").write_text(json.dumps(s))
    r = _cli("report", str(recorded), "--no-vector", cwd=tmp_path)  # PNG only: tests/test_site.py has the vector copies
    assert r.returncode == 0, r.stderr
    cam = json.loads((recorded / "summary.json").read_text())["metrics"]["camera"]
    assert cam["detection_range_m"] == 777.0 and cam["focal_px"] == 1234.0 and cam["image_px"] == 960
    msgs = list(read_mcap(recorded / "run.mcap"))
    # the bandwidth page: `report` above wrote one too, so it is removed first; report-bandwidth must
    # write it again, and its counts are the recording's isl/tx and isl/rx messages, counted here
    bw = recorded / "report" / "bandwidth.html"
    bw.unlink()
    r = _cli("report-bandwidth", str(recorded), cwd=tmp_path)
    assert r.returncode == 0, r.stderr + r.stdout
    assert f"wrote {bw}" in r.stdout and bw.is_file(), r.stdout
    tx = sum(t.startswith("isl/tx/") for t, *_ in msgs)
    rx = sum(t.startswith("isl/rx/") for t, *_ in msgs)
    assert tx > 0 and rx > 0 and f": {tx} transmissions (" in r.stdout and f", {rx} deliveries (" in r.stdout, \
        (tx, rx, r.stdout)
    # the navigation report: it counts the visible pair-steps of the truth with the recorded camera
    # (777 m range, 960 px, f = 1234 px), recounted here (this formation, four craft 120 m apart
    # along-track, gives the default camera the same count: the recorded camera of the metrics is
    # checked above through summary.json)
    r = _cli("report-nav", str(recorded), "--out", str(tmp_path / "nav"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    nav = json.loads((recorded / "navreport" / "nav_summary.json").read_text())
    assert nav["track_rows"] > 0

    def visible(cam: CameraGeometry) -> int:
        n = 0
        for t, _l, _p, m in msgs:
            if t == "truth":
                pos = np.array([[b.position_m.x, b.position_m.y, b.position_m.z] for b in m.bodies])
                n += int(visibility_matrix(pos, cam, np.array([b.alive for b in m.bodies])).sum())
        return n

    recorded_cam, default_cam = visible(CameraGeometry(777.0, 960, 1234.0)), visible(CameraGeometry())
    print("visible pair-steps: recorded camera", recorded_cam, "default camera", default_cam)
    assert recorded_cam > 0 and sum(nav["visible_pair_steps_by_range"].values()) == recorded_cam
    # the replay: a recording that `rerun rrd verify` accepts (not only a file of some size)
    r = _cli("replay", str(recorded / "run.mcap"), "--rrd", str(tmp_path / "replay.rrd"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    from swarmhil.dashboards.viz_node import disable_analytics, rerun_exe

    disable_analytics()
    v = subprocess.run([rerun_exe(), "rrd", "verify", str(tmp_path / "replay.rrd")], capture_output=True, text=True,
                       timeout=120)
    assert v.returncode == 0, v.stdout + v.stderr


@pytest.mark.parametrize("expr, field", [
    ("run.duratoin_s=5", "[run].duratoin_s is not a known field"),            # unknown field
    ("run.duration_s=-1", "[run].duration_s must be > 0"),                   # bad value
    ("link.loss_probability=2", "[link].loss_probability must be in [0, 1]"),  # bad value, owner's check
    ("controller.name=nope", "[controller].name must be one of"),            # allowed values listed
    ("camera.frame_period_s=3", "[camera].frame_period_s is not a known field"),
    ("run.duration_s", "expected section.key=value"),                         # malformed expression
])
def test_set_errors_are_one_line_with_exit_code_2(expr: str, field: str, tmp_path: Path) -> None:
    r = _cli("run", "deploy/scenarios/demo.toml", "--in-process", "--out", str(tmp_path / "x"), "--set", expr)
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert field in lines[0], lines[0]
    assert not (tmp_path / "x").exists()


def test_sweep_takes_set_and_rejects_a_bad_param_before_running(tmp_path: Path) -> None:
    r = _cli("sweep", "deploy/scenarios/demo.toml", "--param", "sensing.roe_noise_fraction", "--values", "0,-1",
             "--set", "run.duration_s=20", "--out", str(tmp_path / "sw"))
    assert r.returncode == 2 and "[sensing].roe_noise_fraction must be >= 0.0" in r.stderr, r.stderr
    r = _cli("sweep", "deploy/scenarios/demo.toml", "--param", "sensing.roe_noise_fraction", "--values", "0",
             "--set", "run.duratoin_s=20", "--out", str(tmp_path / "sw"))
    assert r.returncode == 2 and "[run].duratoin_s is not a known field" in r.stderr, r.stderr
    r = _cli("sweep", "deploy/scenarios/demo.toml", "--param", "sensing.roe_noise_fraction", "--values", "0,0.1",
             "--set", "run.duration_s=20", "--no-case-reports", "--jobs", "1", "--out", str(tmp_path / "sw"))
    assert r.returncode == 0, r.stderr
    cases = sorted((tmp_path / "sw").glob("*/summary.json"))
    assert len(cases) == 2
    for c in cases:
        cfg = json.loads(c.read_text())["config"]
        assert cfg["run"]["duration_s"] == 20.0 and cfg["sets"][0] == "run.duration_s=20"


def test_set_reaches_every_process_of_a_multi_process_run(tmp_path: Path) -> None:
    r = _cli("run", "deploy/scenarios/demo.toml", "--out", str(tmp_path / "mp"), "--set", "run.duration_s=30",
             "--set", "actuator.max_accel_mps2=2e-4", "--no-progress")
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "mp" / "summary.json").read_text())
    assert s["steps"] == 3 and s["config"]["actuator"]["max_accel_mps2"] == 2e-4
    children = json.loads((tmp_path / "mp" / "scenario.json").read_text())
    assert children["sets"] == ["run.duration_s=30", "actuator.max_accel_mps2=2e-4"]
