"""System runs of the backbone: the 24 h drift-20 scenario multi-process (marked `system`),
and the J2 plant through the whole stack in process."""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from conftest import SCENARIOS, read_mcap
from deploy.launcher import MultiProcessRun, run_in_process
from deploy.scenario import load_scenario, parse_scenario
from plant.sensors import CameraGeometry, visibility_matrix, weakly_connected


def _truth_arrays(path: Path, run: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    truth = [m for t, _l, _p, m in read_mcap(path) if t == "truth"]
    t = np.array([m.header.t for m in truth])
    pos = np.array([[[b.position_m.x, b.position_m.y, b.position_m.z] for b in m.bodies] for m in truth])
    roe = np.array([[list(b.roe_m) for b in m.bodies] for m in truth])
    return t, pos, roe


@pytest.mark.system
def test_drift20_24h_multiprocess_disperses_like_fig7(tmp_path: Path) -> None:
    """Paper 002 Fig. 7: without control the along-track separations grow linearly, at the rate
    -3/2 n a*da of each spacecraft, and the swarm falls apart."""
    path = SCENARIOS / "drift-20.toml"
    sc = load_scenario(path)
    res = MultiProcessRun(str(path), sc, tmp_path / "d20", "d20day", progress=False).execute()
    assert res.exit_code == 0, res.reason
    assert res.summary["steps"] == 8640 and res.summary["dead_agents"] == {}
    t, pos, roe = _truth_arrays(tmp_path / "d20" / "run.mcap", "d20day")
    assert len(t) == 8641
    n = sc.orbit.mean_motion_radps
    u = sc.orbit.u0_rad + n * t
    basis = np.column_stack([np.ones_like(t), t, np.sin(u), np.cos(u)])  # secular drift + orbital harmonics
    for i in range(pos.shape[1]):
        slope = np.linalg.lstsq(basis, pos[:, i, 1], rcond=None)[0][1]  # along-track drift rate, m/s
        expected = -1.5 * n * roe[0, i, 0]
        assert slope == pytest.approx(expected, rel=1e-6, abs=1e-9)
    spread0 = np.ptp(pos[0, :, 1])
    spread1 = np.ptp(pos[-1, :, 1])
    assert spread1 > 2 * spread0  # 3.8 km of slots grows to ~11 km in a day (a*da ~ 20 m, 1 sigma)
    cam = CameraGeometry()
    assert weakly_connected(visibility_matrix(pos[0], cam))
    assert not weakly_connected(visibility_matrix(pos[-1], cam))


def test_j2_plant_through_the_stack_stays_close_to_linear(tmp_path: Path) -> None:
    """The j2 fidelity runs end to end; over one orbit a ~km formation stays within metres of the
    Keplerian linear model (J2 differential effects + second-order terms)."""
    doc = tomllib.loads((SCENARIOS / "drift-20.toml").read_text())
    doc["dispersion"]["count"] = 6
    doc["run"]["duration_s"] = 5700.0
    runs = {}
    for fid in ("linear", "j2"):
        d = {**doc, "plant": {"fidelity": fid}}
        sc = parse_scenario(d, f"{fid}.toml")
        run_in_process(sc, tmp_path / fid, fid)
        runs[fid] = _truth_arrays(tmp_path / fid / "run.mcap", fid)[1]
    diff = np.linalg.norm(runs["j2"] - runs["linear"], axis=2)
    assert diff[0].max() < 0.5  # same initial conditions (second-order map terms only)
    assert 1e-3 < diff.max() < 30.0
