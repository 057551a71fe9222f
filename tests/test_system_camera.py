"""System runs of the camera scenarios (issue 4): each runs 24 h multi-process in lockstep (one
process per agent over Zenoh on loopback, the plant, the recorder) and completes with no dead agent.

Marked `system`: each takes minutes (the rendered ones are the slowest: every agent renders and
navigates a 1080 x 1080 frame every 10 s of simulated time). Durations are printed (`pytest -s`).

CI budget: CI has 90 minutes for everything, and on this 2-core machine a rendered 24 h run of 20
agents costs about 20 agents x 8640 frames x 2-4 ms of rendering alone. By default the exact-camera
scenario runs its full 24 h and the two rendered ones their first 6 h; `SWARMHIL_FULL_DAY=1` runs
all three for 24 h (what docs/camera-navigation.md reports).
"""
from __future__ import annotations

import os
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
    assert (tmp_path / "run" / "run.mcap").stat().st_size > 0
