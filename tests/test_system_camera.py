"""System runs of the camera scenarios (issue 4): each runs 24 h multi-process in lockstep (one
process per agent over Zenoh on loopback, the plant, the recorder) and completes with no dead agent.

Marked `system`: each takes minutes (the rendered ones are the slowest: every agent renders and
navigates a 1080 x 1080 frame every 10 s of simulated time). Durations are printed (`pytest -s`).
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest

from conftest import SCENARIOS
from deploy.launcher import MultiProcessRun
from deploy.scenario import load_scenario

CAMERA_SCENARIOS = ["sabatini-20-camera-exact.toml", "sabatini-20-camera-rough.toml", "sabatini-20-camera-filter.toml"]


@pytest.mark.system
@pytest.mark.parametrize("name", CAMERA_SCENARIOS)
def test_camera_scenario_24h_multiprocess_lockstep(name: str, tmp_path: Path) -> None:
    path = SCENARIOS / name
    sc = load_scenario(path)
    assert sc.duration_s == 86400.0 and sc.mode == "lockstep" and sc.sensing["kind"] == "scene"
    run_id = path.stem.replace("sabatini-20-", "sys-")
    t0 = time.monotonic()
    res = MultiProcessRun(str(path), sc, tmp_path / "run", run_id, progress=False).execute()
    wall_s = time.monotonic() - t0
    print(f"\n{name}: 24 h multi-process lockstep in {wall_s:.0f} s wall "
          f"({86400.0 / wall_s:.0f}x real time), total dV {res.summary.get('delta_v_total_mps', float('nan')):.3f} m/s")
    assert res.exit_code == 0, res.reason
    assert res.summary["steps"] == sc.steps == 8640
    assert res.summary["dead_agents"] == {}
    assert all(code == 0 for code in res.summary["exit_codes"].values()), res.summary["exit_codes"]
    assert res.summary["rejected_packets"] == 0
    assert (tmp_path / "run" / "run.mcap").stat().st_size > 0
