"""dashboards/report.py, dashboards/truth_io.py and the `report` / `sweep` commands on tiny in-process runs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import read_mcap

SCENARIO = """
[run]
name = "tiny"
duration_s = 600.0
step_s = 10.0
seed = 3

[controller]
name = "drift-null"
[controller.params]
gain_per_s = 1e-3

[sensing]
roe_noise_fraction = 0.0

[[spacecraft]]
id = "a"
roe_m = [10.0, -300.0, 20.0, 0.0, 20.0, 0.0]

[[spacecraft]]
id = "b"
roe_m = [-5.0, -150.0, 0.0, 25.0, 0.0, 25.0]

[[spacecraft]]
id = "c"
roe_m = [0.0, 0.0, -15.0, 15.0, -15.0, 15.0]

[[spacecraft]]
id = "d"
roe_m = [3.0, 2000.0, 0.0, 0.0, 0.0, 0.0]
"""


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    d = tmp_path_factory.mktemp("tiny")
    (d / "tiny.toml").write_text(SCENARIO)
    run_in_process(load_scenario(d / "tiny.toml"), d / "run", "tiny-run")
    return d / "run"


def test_read_truth_matches_an_independent_decode(tiny_run):
    from swarmhil.dashboards.truth_io import read_truth

    tr = read_truth(tiny_run / "run.mcap")
    msgs = [m for topic, _lt, _pt, m in read_mcap(tiny_run / "run.mcap") if topic == "truth"]
    assert tr.run == "tiny-run" and tr.ids == ["a", "b", "c", "d"]
    assert tr.n_steps == len(msgs) == 61
    last = max(msgs, key=lambda m: m.header.step)
    assert tr.t_s[-1] == pytest.approx(last.header.t) == pytest.approx(600.0)
    assert tr.position_m[-1, 2] == pytest.approx([last.bodies[2].position_m.x, last.bodies[2].position_m.y,
                                                  last.bodies[2].position_m.z])
    assert tr.roe_m[0, 0] == pytest.approx([10.0, -300.0, 20.0, 0.0, 20.0, 0.0])


def test_report_command_writes_figures_and_metrics(tiny_run):
    from swarmhil.dashboards.metrics import delta_v_from_accel
    from swarmhil.dashboards.truth_io import read_truth
    from swarmhil.deploy.cli import main

    res = CliRunner().invoke(main, ["report", str(tiny_run), "--steady-from-h", "0.1"])
    assert res.exit_code == 0, res.output
    # the command says what every run has and which sections the page holds (issue 25: no paper 002 metric)
    assert "total dV" in res.output and "p002-swarm" in res.output.split("sections: ", 1)[1].split("\n")[0]
    assert "weakly connected" not in res.output
    page = tiny_run / "report" / "index.html"
    html = page.read_text()
    for png in ("components.png", "digraph_start.png", "digraph_end.png", "roe_a_l.png", "roe_e.png", "roe_i.png",
                "sep_along.png", "sep_cross.png", "sep_radial.png", "parallelism.png", "accel.png", "dv.png",
                "along_track.png", "projections.png", "closest_approach.png"):
        assert (tiny_run / "report" / png).stat().st_size > 5000
        assert f'src="{png}"' in html or f'href="{png}"' in html  # an image, or the static copy of a Plotly figure
    summary = json.loads((tiny_run / "summary.json").read_text())
    met = summary["metrics"]
    assert met["steady_from_s"] == pytest.approx(360.0)
    # d is 2 km ahead of everyone: the swarm is two weak components from the start
    assert met["connectivity"]["components_start"] == 2 and not met["connectivity"]["always_weakly_connected"]
    assert "d" in met["connectivity"]["sees_nobody_end"]
    # dV: the plant's accounting, the metrics and the integral of the recorded commands agree
    tr = read_truth(tiny_run / "run.mcap")
    dv = delta_v_from_accel(tr.accel_mps2, tr.t_s)
    assert met["control"]["delta_v_total_mps"] == pytest.approx(summary["delta_v_total_mps"], rel=1e-12)
    assert met["control"]["delta_v_total_mps"] > 0
    assert dv[-1].sum() == pytest.approx(summary["delta_v_total_mps"], rel=1e-9)
    for sid, v in summary["delta_v_mps"].items():
        assert met["control"]["delta_v_per_spacecraft_mps"][sid] == pytest.approx(v)
    # closest approach of all pairs is the smaller of the visible / non-visible classes
    ca = met["closest_approach"]
    assert ca["all_pairs"]["distance_m"] == pytest.approx(min(ca["visible_pairs"]["distance_m"],
                                                              ca["non_visible_pairs"]["distance_m"]))
    sampled = np.linalg.norm(tr.position_m[:, :, None] - tr.position_m[:, None, :], axis=-1)
    sampled[:, np.arange(4), np.arange(4)] = np.inf
    assert ca["all_pairs"]["distance_m"] <= sampled.min() + 1e-9


P002_METRICS = ("along-track to closest visible", "orbit-minimum a(|dl|-2|de|)", "radial a|de|", "parallelism",
                "always weakly connected")
OVERVIEW = ("total dV [m/s]", "dV per spacecraft [m/s]", "max |a| [m/s^2]", "closest approach, all pairs", "link traffic",
            "events")


def overview_of(page: str) -> str:
    """The overview of a report page: everything before the first section heading."""
    return page.split("<h2", 1)[0]


def test_paper002_metrics_are_in_its_section_not_in_the_overview(tiny_run):
    """Issue 25: the overview is what every mission has; paper 002's ROE metrics and figures are its
    section's (missions/p002_sabatini/report.py), with the same rows and figures as before."""
    from swarmhil.dashboards.report import write_report

    page = write_report(tiny_run, steady_from_s=360.0, interactive=False, export=()).read_text()
    overview, section = overview_of(page), page.split('<h2 id="p002-swarm">', 1)[1].split("<h2", 1)[0]
    for word in P002_METRICS:
        assert word not in overview and word in section, word
    for word in OVERVIEW:
        assert word in overview, word
    assert "no link in this run" in overview  # the tiny run has no link
    assert "t &gt;= 6 min" in section and "in visibility" in section
    for png in ("components.png", "digraph_start.png", "sep_along.png", "dv.png", "closest_approach.png"):
        assert png in section and png not in overview, png
    summary = json.loads((tiny_run / "summary.json").read_text())
    assert "p002-swarm" not in summary["metrics"]  # paper 002's metrics stay where they were
    assert summary["metrics"]["connectivity"]["always_weakly_connected"] is False


def test_parse_values_and_set_param():
    from swarmhil.deploy.cli_report import parse_values, set_param

    assert parse_values("0,0.1, 0.35") == [0, 0.1, 0.35]
    assert parse_values("[1,2,3],[4,5,6],x") == [[1, 2, 3], [4, 5, 6], "x"]
    doc = {"sensing": {"kind": "rel"}}
    new = set_param(doc, "sensing.roe_noise_fraction", 0.3)
    assert new["sensing"] == {"kind": "rel", "roe_noise_fraction": 0.3} and "roe_noise_fraction" not in doc["sensing"]
    assert set_param(doc, "controller.params.k_ecc", 1.2)["controller"]["params"]["k_ecc"] == 1.2


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; fails on anything that is not a PNG."""
    import struct

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR", path
    return struct.unpack(">II", data[16:24])


def test_sweep_command_runs_cases_in_parallel(tmp_path):
    from swarmhil.deploy.cli import main

    (tmp_path / "tiny.toml").write_text(SCENARIO)
    out = tmp_path / "sweep"
    res = CliRunner().invoke(main, ["sweep", str(tmp_path / "tiny.toml"), "--param", "controller.params.gain_per_s",
                                    "--values", "0,1e-3", "--duration", "200", "--out", str(out), "--jobs", "2",
                                    "--no-case-reports"])
    assert res.exit_code == 0, res.output
    sweep = json.loads((out / "sweep.json").read_text())
    assert [c["value"] for c in sweep["cases"]] == [0, 1e-3]
    dv = [c["delta_v_total_mps"] for c in sweep["cases"]]
    assert dv[0] == 0.0 and dv[1] > 0.0
    html = (out / "report" / "index.html").read_text()
    assert "controller.params.gain_per_s" in html and "<td>0.001</td>" in html and "<td>0.00174</td>" in html
    for png in ("sweep_dv_connectivity.png", "sweep_components_dv_time.png"):
        assert f'src="{png}"' in html
        w, h = _png_size(out / "report" / png)
        assert w > 300 and h > 200, (png, w, h)  # a real figure, not an empty or broken file
    from swarmhil.dashboards.truth_io import read_truth

    for c in sweep["cases"]:
        assert not (Path(c["dir"]) / "report").exists()
        series = np.load(Path(c["dir"]) / "metrics_series.npz")
        tr = read_truth(Path(c["dir"]) / "run.mcap")
        # one sample per truth step (200 s of 10 s steps), the cumulative dV of the plant's accounting
        np.testing.assert_array_equal(series["t_s"], tr.t_s)
        assert series["t_s"].tolist() == [10.0 * k for k in range(21)]
        dv_truth = [sum(b.delta_v_mps for b in m.bodies) for t, _l, _p, m in read_mcap(Path(c["dir"]) / "run.mcap")
                    if t == "truth"]
        np.testing.assert_allclose(series["delta_v_total_mps"], dv_truth, rtol=1e-12, atol=0)
        assert series["delta_v_total_mps"][-1] == pytest.approx(c["delta_v_total_mps"], rel=1e-12)
        # d is 2 km ahead of everyone (detection range 500 m): two weak components, a, b, c together
        assert series["n_components"].tolist() == [2] * 21 and series["largest"].tolist() == [3] * 21
    again = CliRunner().invoke(main, ["report", str(out)])  # a sweep directory: every case and the sweep again
    assert again.exit_code == 0, again.output
    assert json.loads((out / "sweep.json").read_text())["cases"][1]["delta_v_total_mps"] == dv[1]
    bad = CliRunner().invoke(main, ["sweep", str(tmp_path / "tiny.toml"), "--param", "sensing.roe_noise_fraction",
                                    "--values", "-1", "--out", str(tmp_path / "bad")])
    assert bad.exit_code != 0 and "roe_noise_fraction" in bad.output


def test_accel_alignment_from_either_recording_convention():
    """accel_cmd_mps2 of step k was 'applied over [t_k, t_k+1)' in early recordings and is 'applied over
    [t_k-1, t_k)' now; the dV increments tell which, and both give the same aligned commands."""
    from swarmhil.dashboards.truth_io import align_accel

    rng = np.random.default_rng(2)
    t = np.arange(0.0, 60.0, 10.0)
    applied = rng.normal(0.0, 1e-4, (t.size, 3, 3))
    applied[-1] = 0.0  # nothing is applied after the last sample
    dv = np.vstack([np.zeros((1, 3)), np.cumsum(np.linalg.norm(applied[:-1], axis=-1) * 10.0, axis=0)])
    starts = applied.copy()
    ended = np.zeros_like(applied)
    ended[1:] = applied[:-1]
    for recorded, label in ((starts, "starts"), (ended, "ended")):
        got, how = align_accel(recorded, dv, t)
        assert how == label
        assert np.array_equal(got, applied)
