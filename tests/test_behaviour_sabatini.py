"""Decision logic of the paper 002 behavioural controller (missions/p002_sabatini/fsw/sabatini.py).

Relative states are built from ROE with the plant's own map (plant/dynamics/roe_linear.py), so the
flight software's measurement inversion is checked against the truth model.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from swarmhil.missions.p002_sabatini.fsw.sabatini import (ALIGN, ALIGN_DRIFT, ATTRACT, CA, SabatiniController, SabatiniParams,
                                      relative_roe_observer)
from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.agent.roe import input_matrix
from swarmhil.plant.dynamics import roe_linear as truth

A_M = 6878137.0
N_RADPS = truth.mean_motion(A_M)
ORBIT = OrbitInfo(A_M, N_RADPS)
REPO = Path(__file__).resolve().parents[1]


def _obs(roe_j: np.ndarray, roe_ks: list[np.ndarray], u: float, step: int = 0) -> Observation:
    """Observation of j: LVLH states of each k relative to j (r_k - r_j), from the plant's map."""
    p_j, v_j = truth.roe_to_lvlh(np.asarray(roe_j, float), u, N_RADPS)
    p_k, v_k = truth.roe_to_lvlh(np.asarray(roe_ks, float), u, N_RADPS)
    return Observation(step=step, t_s=10.0 * step, u_rad=u, neighbour_ids=[f"k{i}" for i in range(len(roe_ks))],
                       rel_position_m=p_k - p_j, rel_velocity_mps=v_k - v_j)


def _ctrl(**params) -> SabatiniController:
    return make_controller("sabatini", "sc01", ORBIT, params)


def test_measurement_is_turned_around_to_observer_relative_to_neighbour():
    rng = np.random.default_rng(3)
    roe_j, roe_k = rng.normal(scale=50, size=6), rng.normal(scale=50, size=6)
    obs = _obs(roe_j, [roe_k], 1.3)
    got = relative_roe_observer(obs.rel_position_m, obs.rel_velocity_mps, 1.3, N_RADPS)
    np.testing.assert_allclose(got[0], roe_j - roe_k, atol=1e-8)
    cmd = _ctrl().step(obs)
    np.testing.assert_allclose(cmd.decisions[0].roe_rel_m, roe_j - roe_k, atol=1e-8)


@pytest.mark.parametrize("dl_m, expected", [(-160.0, CA), (-260.0, ALIGN_DRIFT), (-400.0, ATTRACT)])
def test_behaviour_from_decision_distance(dl_m, expected):
    """d_min_jk = |a dl| - 2 |a de| with |a de| = 40 m: 80 m (CA), 180 m (alignment), 320 m (attraction)."""
    rel = np.array([0.0, dl_m, 40.0, 0.0, 40.0, 0.0])
    cmd = _ctrl().step(_obs(rel, [np.zeros(6)], 0.4))
    d = cmd.decisions[0]
    assert d.behaviour == expected
    assert d.d_min_m == pytest.approx(abs(dl_m) - 80.0, abs=1e-8)


def test_collision_avoidance_makes_the_observer_drift_back():
    """j trails k inside d_min with de, di already at their CA reference: the command raises j's
    semi-major axis (d(a da)/dt > 0), so j drifts back (d dl/dt = -3/2 n da), away from k."""
    p = SabatiniParams()
    ref = p.k_ecc * p.d_min_trans_m
    rel = np.array([0.0, -120.0, ref, 0.0, ref, 0.0])  # d_min_jk = 120 - 66 = 54 m
    for u in np.linspace(0.0, 2 * np.pi, 9):
        cmd = _ctrl().step(_obs(rel, [np.zeros(6)], u))
        assert cmd.mode == CA
        rate = A_M * input_matrix(u, A_M, N_RADPS) @ cmd.accel_mps2
        assert rate[0] > 0.0
        np.testing.assert_allclose(rate[4:], 0.0, atol=1e-9 * abs(rate[0]))  # no cross-track action


def test_alignment_flags_of_algorithm_1():
    ctrl = _ctrl()
    p = ctrl.p
    # TooLarge through di (|a di| = 150 m > 0.9 * range * tan(28.37 deg) for a range of ~300 m)
    rel = np.array([0.0, -250.0, 35.0, 0.0, 0.0, 150.0])
    obs = _obs(rel, [np.zeros(6)], 0.2)
    roe = relative_roe_observer(obs.rel_position_m, obs.rel_velocity_mps, obs.u_rad, N_RADPS)
    ref, w, correct = ctrl.references(roe, np.linalg.norm(obs.rel_position_m, axis=1), ctrl.classify(np.array([180.0])))
    assert correct[0]
    np.testing.assert_allclose(ref[0, 2:4], [p.k_ecc * p.d_min_trans_m, 0.0], atol=1e-9)
    np.testing.assert_allclose(ref[0, 4:6], ref[0, 2:4], atol=0)
    assert ref[0, 0] == 0.0 and w[0] == pytest.approx(0.6)  # (300 - 180) / (300 - 100)
    # parallel, big enough, drift-free: nothing to correct, no command
    good = np.array([0.0, -260.0, 24.0, 32.0, 24.0, 32.0])  # |de| = |di| = 40 m, parallel
    cmd = ctrl.step(_obs(good, [np.zeros(6)], 0.2))
    assert cmd.decisions[0].behaviour == ALIGN_DRIFT
    np.testing.assert_allclose(cmd.accel_mps2, 0.0, atol=1e-18)
    # the same geometry with orthogonal de / di is NotParallel
    bad = np.array([0.0, -260.0, 40.0, 0.0, 0.0, 40.0])
    assert ctrl.step(_obs(bad, [np.zeros(6)], 0.2)).decisions[0].behaviour == ALIGN


def test_alignment_weight_is_linear_between_region_borders():
    ctrl = _ctrl()
    roe = np.array([[0.0, -d, 0.0, 0.0, 0.0, 0.0] for d in (100.0, 200.0, 299.0)])
    _, w, _ = ctrl.references(roe, np.abs(roe[:, 1]), ctrl.classify(np.abs(roe[:, 1])))
    np.testing.assert_allclose(w, [1.0, 0.5, 0.005], atol=1e-12)


def test_command_is_sum_over_neighbours_and_clipped():
    ctrl = _ctrl()
    ks = [np.array([1.0, 150.0, 5.0, 0.0, 0.0, 5.0]), np.array([-2.0, 90.0, 0.0, 10.0, 3.0, 0.0])]  # alignment, CA
    both = ctrl.step(_obs(np.zeros(6), ks, 0.9))
    single = [ctrl.step(_obs(np.zeros(6), [k], 0.9)).accel_mps2 for k in ks]
    np.testing.assert_allclose(both.accel_mps2, single[0] + single[1], atol=1e-18)
    assert [d.behaviour for d in both.decisions] == [ALIGN, CA] and both.mode == CA
    tiny = _ctrl(max_accel_mps2=1e-6).step(_obs(np.zeros(6), ks, 0.9))
    np.testing.assert_allclose(tiny.accel_mps2, np.clip(both.accel_mps2, -1e-6, 1e-6), atol=0)


def test_disabled_behaviours_and_empty_sky():
    ctrl = _ctrl(enable_alignment=False, enable_attraction=False)
    cmd = ctrl.step(_obs(np.array([0.0, -400.0, 0, 0, 0, 0]), [np.zeros(6)], 0.0))
    assert cmd.decisions[0].behaviour == f"{ATTRACT}_disabled" and cmd.mode == "coast"
    np.testing.assert_array_equal(cmd.accel_mps2, np.zeros(3))
    empty = Observation(0, 0.0, 0.0, [], np.zeros((0, 3)), np.zeros((0, 3)))
    out = ctrl.step(empty)
    assert out.mode == "search" and not out.decisions
    np.testing.assert_array_equal(out.accel_mps2, np.zeros(3))


def test_unknown_or_malformed_params_are_rejected():
    with pytest.raises(ValueError, match="d_min"):
        _ctrl(d_min=100.0)
    with pytest.raises(ValueError, match="6 entries"):
        _ctrl(q_ca=[1.0, 0.0])


def _fixed_observations() -> list[Observation]:
    rng = np.random.default_rng(7)
    obs = []
    for step in range(20):
        ks = [rng.normal(scale=[5, 200, 30, 30, 30, 30]) for _ in range(5)]
        obs.append(_obs(rng.normal(scale=[5, 50, 20, 20, 20, 20]), ks, 0.37 * step, step))
    return obs


def test_deterministic_in_process_and_across_processes(tmp_path):
    obs = _fixed_observations()
    a = [_ctrl().step(o).accel_mps2 for o in obs]
    b = [_ctrl().step(o).accel_mps2 for o in obs]
    c_ctrl = _ctrl()
    c = [c_ctrl.step(o).accel_mps2 for o in reversed(obs)][::-1]  # no hidden state between steps
    for x, y, z in zip(a, b, c):
        assert x.tobytes() == y.tobytes() == z.tobytes()
    np.savez(tmp_path / "obs.npz", u=[o.u_rad for o in obs], p=[o.rel_position_m for o in obs],
             v=[o.rel_velocity_mps for o in obs])
    script = f"""
import json, numpy as np
from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
d = np.load({str(tmp_path / 'obs.npz')!r})
c = make_controller("sabatini", "sc01", OrbitInfo({A_M!r}, {N_RADPS!r}), {{}})
out = [c.step(Observation(i, 10.0 * i, float(u), [f"k{{j}}" for j in range(5)], p, v)).accel_mps2.tobytes().hex()
       for i, (u, p, v) in enumerate(zip(d["u"], d["p"], d["v"]))]
print(json.dumps(out))
"""
    res = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, check=True)
    assert json.loads(res.stdout) == [x.tobytes().hex() for x in a]
