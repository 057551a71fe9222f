"""Periodic DRE gains of paper 002 section 3.4 (missions/p002_sabatini/fsw/dre.py).

- the tabulated P(u) is a fixed point of one more backward orbit of the DRE (periodic);
- the gains agree with an independent discrete-time periodic LQR built on the plant's exact
  zero-order-hold model (plant/dynamics/roe_linear.py) with a 10 s step;
- the closed loop (plant ZOH propagation, gains of the table, command held over each step) has
  its Floquet multipliers inside the unit circle on the weighted states; the unweighted states
  (dl always; de, di for attraction) are neutral by construction (multiplier exactly 1), because
  Q gives them no weight and the DRE gives them no gain.
"""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.missions.p002_sabatini.fsw.dre import gain_table, integrate_riccati_one_orbit
from swarmhil.plant.dynamics import roe_linear as truth

A_M = 6878137.0
N_RADPS = truth.mean_motion(A_M)
PERIOD_S = 2.0 * np.pi / N_RADPS
# (Q diag, R in SI) of collision avoidance, alignment, attraction (NOTES-002)
WEIGHTS = {
    "ca": ((0.01, 0.0, 1.0, 1.0, 1.0, 1.0), 1e-2),
    "al": ((1.0, 0.0, 1.0, 1.0, 1.0, 1.0), 1.0),
    "att": ((1.0, 0.0, 0.0, 0.0, 0.0, 0.0), 1e-1),
}


@pytest.mark.parametrize("name", list(WEIGHTS))
def test_riccati_table_is_periodic(name):
    q, r = WEIGHTS[name]
    table = gain_table(A_M, N_RADPS, q, r)
    p0 = table.riccati[0]
    sol = integrate_riccati_one_orbit(p0, A_M, N_RADPS, np.array(q), np.full(3, r))
    p_again = sol.sol(table.u_grid_rad / N_RADPS).T.reshape(-1, 6, 6)
    scale = np.max(np.abs(table.riccati))
    assert np.max(np.abs(p_again - table.riccati)) < 1e-6 * scale
    # P is symmetric positive semi-definite; K varies with u except for attraction, whose only
    # weighted state da is driven by the constant entry 2/(a n) of B (so its gain is constant)
    assert np.min(np.linalg.eigvalsh(table.riccati)) > -1e-9 * scale
    variation = np.ptp(table.gain_per_s2, axis=0).max() / np.abs(table.gain_per_s2).max()
    assert variation > 0.1 if name != "att" else variation < 1e-6
    # interpolation wraps: gain(2 pi) == gain(0)
    np.testing.assert_allclose(table.gain(2.0 * np.pi), table.gain(0.0), atol=0)


@pytest.mark.parametrize("name", list(WEIGHTS))
def test_gains_match_discrete_periodic_lqr_on_plant_zoh(name):
    """Discrete periodic Riccati recursion on the plant's exact ZOH model, cost sum (x'Q x/a^2 + u'R u) dt."""
    q, r = WEIGHTS[name]
    table = gain_table(A_M, N_RADPS, q, r)
    steps = 568
    dt_s = PERIOD_S / steps
    phi = truth.transition_matrix(N_RADPS, dt_s)
    gammas = [truth.zoh_input_matrix(k * dt_s * N_RADPS, N_RADPS, dt_s) for k in range(steps)]
    q_d, r_d = np.diag(q) / A_M**2 * dt_s, np.eye(3) * r * dt_s
    p = table.riccati[0] / A_M**2  # warm start; the recursion converges to its own fixed point
    for _ in range(8):
        for k in reversed(range(steps)):
            g = gammas[k]
            k_d = np.linalg.solve(r_d + g.T @ p @ g, g.T @ p @ phi)
            p = q_d + phi.T @ p @ (phi - g @ k_d)
            p = 0.5 * (p + p.T)
            if k % 71 == 0:
                np.testing.assert_allclose(k_d, table.gain(k * dt_s * N_RADPS), rtol=0,
                                           atol=0.03 * np.abs(table.gain_per_s2).max())


def _monodromy(name: str, dt_s: float, steps: int) -> np.ndarray:
    """Closed-loop transition over `steps` ZOH steps, built column by column with the plant propagator."""
    q, r = WEIGHTS[name]
    table = gain_table(A_M, N_RADPS, q, r)
    x = np.eye(6)  # six unit ROE states (metres), propagated together
    for k in range(steps):
        u = k * dt_s * N_RADPS
        accel = -(table.gain(u) @ x.T).T
        x = truth.propagate_roe(x, accel, u, N_RADPS, dt_s)
    return x.T


@pytest.mark.parametrize("name", list(WEIGHTS))
def test_closed_loop_floquet_multipliers_with_10s_hold(name):
    q, _ = WEIGHTS[name]
    w = np.array(q) > 0
    steps = round(PERIOD_S / 10.0)  # 568 steps of 9.9955 s: exactly one orbit, so the ZOH loop is periodic
    mono = _monodromy(name, PERIOD_S / steps, steps)
    # the weighted states are not driven by the unweighted ones, so their block carries their multipliers
    assert np.max(np.abs(mono[np.ix_(w, ~w)])) < 1e-12
    mult = np.linalg.eigvals(mono[np.ix_(w, w)])
    assert np.max(np.abs(mult)) < 0.9, mult
    np.testing.assert_allclose(mono[np.ix_(~w, ~w)], np.eye(int((~w).sum())), atol=1e-12)
    # and with exactly 10 s: the weighted states contract over 5 orbits
    mono10 = _monodromy(name, 10.0, 5 * steps)
    assert np.max(np.abs(np.linalg.eigvals(mono10[np.ix_(w, w)]))) < 0.9**5
