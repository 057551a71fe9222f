"""System runs of the camera scenarios (issue 4): each runs 24 h multi-process in lockstep (one
process per agent over Zenoh on loopback, the plant, the recorder) and completes with no dead agent.

Marked `system`: each takes minutes (the rendered ones are the slowest: every agent renders and
navigates a 1080 x 1080 frame every 10 s of simulated time). Durations are printed (`pytest -s`).

CI budget: CI has 90 minutes for everything. Measured here (quiet 2-core machine, numba render
backend), a 24 h run took 645 s (exact) and 600 s (rendered rough); the filter costs more (an EKF
per track). By default the exact-camera scenario runs its full 24 h and the two rendered ones their
first 6 h; `SWARMHIL_FULL_DAY=1` runs all three for 24 h (what docs/camera-navigation.md reports).
The filter run is also checked against issue 4's goal: ideal sensing over the same span runs
in-process, and the filter must stay weakly connected per orbit and cost <= 1.5x its dV.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from conftest import SCENARIOS
from swarmhil.deploy.launcher import MultiProcessRun
from swarmhil.deploy.scenario import load_scenario

CAMERA_SCENARIOS = ["sabatini-20-camera-exact.toml", "sabatini-20-camera-rough.toml", "sabatini-20-camera-filter.toml"]


@pytest.mark.system
@pytest.mark.timeout(1500)  # the 24 h exact run took 645 s on a quiet machine: past the default 600 s
@pytest.mark.parametrize("name", CAMERA_SCENARIOS)
def test_camera_scenario_24h_multiprocess_lockstep(name: str, tmp_path: Path) -> None:
    path = SCENARIOS / name
    sc = load_scenario(path)
    assert sc.duration_s == 86400.0 and sc.mode == "lockstep" and sc.sensing["kind"] == "scene"
    full_day = os.environ.get("SWARMHIL_FULL_DAY") == "1" or "exact" in name
    duration = 86400.0 if full_day else 21600.0
    sc = sc.with_overrides(duration_s=duration)
    run_id = path.stem.replace("sabatini-20-", "sys-")
    t0 = time.monotonic()
    res = MultiProcessRun(str(path), sc, tmp_path / "run", run_id, progress=False,
                          overrides={"duration": duration}).execute()
    wall_s = time.monotonic() - t0
    print(f"\n{name}: {duration / 3600:.0f} h multi-process lockstep in {wall_s:.0f} s wall "
          f"({duration / wall_s:.0f}x real time), total dV {res.summary.get('delta_v_total_mps', float('nan')):.3f} m/s")
    assert res.exit_code == 0, res.reason
    assert res.summary["steps"] == sc.steps == int(duration / 10.0)
    assert res.summary["dead_agents"] == {}
    assert all(code == 0 for code in res.summary["exit_codes"].values()), res.summary["exit_codes"]
    assert res.summary["rejected_packets"] == 0
    assert res.summary["agent_faults"] == {}, res.summary["agent_faults"]  # no navigation or controller fault
    assert (tmp_path / "run" / "run.mcap").stat().st_size > 0
    if "filter" in name:  # issue 4's goal, against ideal sensing over the same span, measured here
        _check_filter_against_ideal(tmp_path, duration)
        _check_refly(tmp_path / "run", "sc07")


def _check_refly(run_dir: Path, sid: str) -> None:
    """`swarmhil refly` (issue 26) on this multi-process recording: the agent's camera, EKF and
    controller re-flown alone reproduce its every command bit for bit; the wall is printed."""
    from swarmhil.deploy.refly import agent_config_of, read_recorded, refly

    t0 = time.monotonic()
    rec = read_recorded(run_dir, sid)
    res = refly(rec, agent_config_of(rec))
    print(f"refly {sid}: {res.verdict()}; read and re-flown in {time.monotonic() - t0:.0f} s wall")
    assert res.diffs == [] and res.steps == len(rec.acts) > 0


def _check_filter_against_ideal(tmp_path: Path, duration: float) -> None:
    """The EKF on rendered images keeps the swarm weakly connected (the union of the visibility
    digraphs over each orbit, as ideal sensing does) and costs at most 1.5x the dV of ideal sensing."""
    import json

    from swarmhil.dashboards.report import write_report
    from swarmhil.deploy.launcher import run_in_process

    ideal = load_scenario(SCENARIOS / "sabatini-20.toml").with_overrides(duration_s=duration)
    run_in_process(ideal, tmp_path / "ideal", "sys-ideal", progress=False)
    met = {}
    for case in ("run", "ideal"):
        write_report(tmp_path / case, figures=False)
        met[case] = json.loads((tmp_path / case / "summary.json").read_text())["metrics"]
    dv = {c: m["control"]["delta_v_total_mps"] for c, m in met.items()}
    union = {c: m["connectivity"]["orbit_union_weakly_connected_fraction"] for c, m in met.items()}
    print(f"filter vs ideal over {duration / 3600:.0f} h: dV {dv['run']:.3f} / {dv['ideal']:.3f} m/s "
          f"= {dv['run'] / dv['ideal']:.2f}x; orbit-union weakly connected {union['run']:.3f} / {union['ideal']:.3f}")
    assert union["ideal"] == 1.0 and union["run"] == 1.0
    assert dv["run"] <= 1.5 * dv["ideal"]
