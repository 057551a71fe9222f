"""The 20-spacecraft scenario of paper 002 (sabatini-20, sabatini-20-explicit) and its report.

Fast: the explicit scenario holds exactly the generated initial conditions, which start weakly
connected. System (`-m system`): the 24 h multi-process lockstep run and `swarmhil report`, and the
explicit scenario giving the same truth as the generated one.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS


def test_explicit_scenario_has_the_generated_initial_conditions():
    from swarmhil.deploy.scenario import load_scenario
    from swarmhil.plant.dynamics.roe_linear import roe_to_lvlh
    from swarmhil.plant.sensors import CameraGeometry, visibility_matrix, weakly_connected

    gen = load_scenario(SCENARIOS / "sabatini-20.toml")
    exp = load_scenario(SCENARIOS / "sabatini-20-explicit.toml")
    assert gen.ids == exp.ids and len(gen.ids) == 20
    assert np.array_equal(gen.roe_m, exp.roe_m)  # bit for bit
    for sc in (gen, exp):
        assert sc.controller == "sabatini" and sc.duration_s == 86400.0 and sc.sensing["roe_noise_fraction"] == 0.0
    pos, _ = roe_to_lvlh(gen.roe_m, gen.orbit.u0_rad, gen.orbit.mean_motion_radps)
    assert weakly_connected(visibility_matrix(pos, CameraGeometry(**gen.camera)))
    # deployment-like: no near-coincident pair, a few kilometres of along-track spread
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(20) * 1e9
    assert d.min() > 20.0
    assert 2000.0 < np.ptp(pos[:, 1]) < 6000.0


def _cli(*args: str, timeout_s: float) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout_s)


@pytest.mark.system
def test_sabatini20_24h_multiprocess_run_and_report(tmp_path):
    out = tmp_path / "s20"
    res = _cli("run", str(SCENARIOS / "sabatini-20.toml"), "--out", str(out), "--no-progress", timeout_s=7200)
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["process_mode"] == "multi-process" and summary["steps"] == 8640
    assert summary["dead_agents"] == {} and summary["rejected_packets"] == 0
    res = _cli("report", str(out), timeout_s=1800)
    assert res.returncode == 0, res.stderr[-3000:]
    met = json.loads((out / "summary.json").read_text())["metrics"]
    assert (out / "report" / "index.html").is_file()
    assert met["control"]["delta_v_total_mps"] == pytest.approx(summary["delta_v_total_mps"])
    assert met["t_end_s"] == pytest.approx(86400.0)


@pytest.mark.system
def test_explicit_scenario_gives_the_same_truth_as_the_generated_one(tmp_path):
    from swarmhil.dashboards.truth_io import read_truth
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    truths = []
    for name in ("sabatini-20", "sabatini-20-explicit"):
        sc = load_scenario(SCENARIOS / f"{name}.toml").with_overrides(duration_s=3600.0)
        run_in_process(sc, tmp_path / name, f"{name}-1h")
        truths.append(read_truth(tmp_path / name / "run.mcap"))
    a, b = truths
    assert a.n_steps == b.n_steps == 361
    assert np.array_equal(a.position_m, b.position_m) and np.array_equal(a.delta_v_mps, b.delta_v_mps)
    assert a.delta_v_mps[-1].sum() > 0.0


def p002_section(page: str) -> tuple[list[list[str]], list[str]]:
    """The table rows ([name, cell]) and the figure files of paper 002's section of a report page."""
    import re

    sec = page.split('<h2 id="p002-swarm">', 1)[1].split("<h2", 1)[0]
    rows = [list(r) for r in re.findall(r"<tr><th>(.*?)</th><td>(.*?)</td></tr>", sec)]
    return rows, sorted(set(re.findall(r'(?:src|href)="([^"/]+\.png)"', sec)))


def test_paper002_section_is_unchanged_by_its_room(tmp_path):
    """Issue 25 step 2: paper 002's report moved into missions/p002_sabatini/report.py with the same
    content: a 20 min sabatini-20 run's section has the rows, values and figures that main's gave
    before the move (tests/data/p002_section_sabatini20_20min.json, same machine class: the values are
    printed to 3 significant digits), and the overview none of them."""
    from swarmhil.dashboards.report import write_report
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    want = json.loads((ROOT / "tests" / "data" / "p002_section_sabatini20_20min.json").read_text())
    sc = load_scenario(SCENARIOS / "sabatini-20.toml").with_overrides(duration_s=want["duration_s"])
    run_in_process(sc, tmp_path / "run", "s20-short", record="truth")
    page = write_report(tmp_path / "run", interactive=False, export=()).read_text()
    rows, figures = p002_section(page)
    assert rows == want["rows"] and figures == want["figures"]
    overview = page.split("<h2", 1)[0]
    for name, _cell in rows:
        assert name.strip() not in overview, name
    for word in ("parallelism", "orbit-minimum", "weakly connected", ".png"):
        assert word not in overview, word
    assert "dV per spacecraft" in overview and "closest approach, all pairs" in overview
