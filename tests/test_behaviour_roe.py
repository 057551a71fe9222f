"""The flight software's ROE model (agent/roe.py) against the plant's truth model (plant/dynamics/roe_linear.py).

DESIGN.md: the two are written independently from the same published equations (NOTES-002), and a
test checks that they agree. B(u) is also checked against the plant's exact zero-order-hold
propagation (a finite difference over a short step), so a sign error in either shows up.
"""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.agent import roe as fsw
from swarmhil.plant.dynamics import roe_linear as truth

A_M = 6878137.0
N_RADPS = truth.mean_motion(A_M)


def _random_roe(seed: int, count: int = 50) -> np.ndarray:
    return np.random.default_rng(seed).normal(scale=[20, 300, 40, 40, 40, 40], size=(count, 6))


def test_maps_agree_with_plant_to_micrometres():
    roe_m = _random_roe(1)
    for u in np.linspace(0.0, 2.0 * np.pi, 13):
        p_f, v_f = fsw.roe_to_lvlh(roe_m, u, N_RADPS)
        p_t, v_t = truth.roe_to_lvlh(roe_m, u, N_RADPS)
        np.testing.assert_allclose(p_f, p_t, atol=1e-9)
        np.testing.assert_allclose(v_f, v_t, atol=1e-12)
        np.testing.assert_allclose(fsw.lvlh_to_roe(p_t, v_t, u, N_RADPS), roe_m, atol=1e-8)


def test_single_state_shapes():
    p, v = fsw.roe_to_lvlh(np.arange(6.0), 0.3, N_RADPS)
    assert p.shape == (3,) and v.shape == (3,)
    assert fsw.lvlh_to_roe(p, v, 0.3, N_RADPS).shape == (6,)


def test_input_matrix_matches_plant_zoh_propagation():
    """a B(u) equals d(roe)/d(accel) per unit time of the plant's exact ZOH solution for a short step."""
    dt_s = 1e-3
    for u in (0.0, 0.7, 2.0, 4.4):
        accel = np.eye(3) * 1e-4
        moved = truth.propagate_roe(np.zeros((3, 6)), accel, u, N_RADPS, dt_s)
        numeric = moved.T / (1e-4 * dt_s)
        np.testing.assert_allclose(A_M * fsw.input_matrix(u, A_M, N_RADPS), numeric, rtol=1e-6, atol=1e-2)  # O(dt) terms ~1.5e-3
        np.testing.assert_allclose(fsw.state_matrix(N_RADPS), truth.state_matrix(N_RADPS), atol=0)


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_observer_roe_rows_is_lvlh_to_roe_of_the_negated_rows_bit_for_bit() -> None:
    """agent/roe.observer_roe_rows (issue 16: the controller's per-pair map, fewer numpy calls)."""
    rng = np.random.default_rng(16)
    for p_ in (0, 1, 7, 120):
        for _ in range(100):
            rp = rng.normal(scale=300.0, size=(p_, 3)) * 10.0 ** rng.integers(-4, 3)
            rv = rng.normal(scale=0.3, size=(p_, 3)) * 10.0 ** rng.integers(-4, 3)
            for a in (rp, rv):
                a[rng.random(a.shape) < 0.03] = rng.choice([0.0, -0.0, np.nan, np.inf, 1e-320], size=1)
            u = float(rng.uniform(-1.0, 1000.0))
            want = fsw.lvlh_to_roe(-rp, -rv, u, N_RADPS)
            got = fsw.observer_roe_rows(rp, rv, u, N_RADPS)
            assert got.shape == want.shape and got.tobytes() == want.tobytes()
