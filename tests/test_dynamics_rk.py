"""The DOP853 tableau copied into plant/dynamics/rk_tableau.py against scipy's, and its order."""
from __future__ import annotations

import numpy as np

from swarmhil.plant.dynamics.rk_tableau import DOP853_A, DOP853_B, DOP853_C, DOP853_N_STAGES, rk_step


def test_tableau_equals_scipy_bit_for_bit() -> None:
    # The private module is imported here only as the independent source of the literals.
    from scipy.integrate._ivp import dop853_coefficients as ref

    assert DOP853_N_STAGES == ref.N_STAGES
    assert np.array_equal(DOP853_A, ref.A[: ref.N_STAGES, : ref.N_STAGES])
    assert np.array_equal(DOP853_B, ref.B)
    assert np.array_equal(DOP853_C, ref.C[: ref.N_STAGES])


def test_tableau_consistency() -> None:
    """Row sums of A equal c, weights sum to 1 (Hairer I, eq. II.1.9)."""
    np.testing.assert_allclose(DOP853_A.sum(axis=1), DOP853_C, atol=1e-14)
    assert abs(DOP853_B.sum() - 1.0) < 1e-14


def test_order_eight_on_harmonic_oscillator() -> None:
    """Global error over a fixed span falls as h^8: halving h divides it by about 2^8 = 256."""

    def f(_t: float, y: np.ndarray) -> np.ndarray:
        return np.array([y[1], -y[0]])

    def err(n_steps: int) -> float:
        y, h = np.array([1.0, 0.0]), 4.0 / n_steps
        for k in range(n_steps):
            y = rk_step(f, k * h, y, h)
        return float(np.hypot(y[0] - np.cos(4.0), y[1] + np.sin(4.0)))

    ratio = err(4) / err(8)
    assert 150.0 < ratio < 450.0, ratio
