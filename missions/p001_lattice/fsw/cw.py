"""The far layer (paper 001 eq. 1-2): a ballistic Clohessy-Wiltshire velocity field.

Frame: CW/Hill at the reference point, x radial outward, y along-track, z orbit normal;
xdd = 3n^2 x + 2n yd, ydd = -2n xd, zdd = -n^2 z.

Eq. 1-2 are garbled in the text; the reading used (NOTES-001): the desired velocity is the one
that puts the agent on the natural CW arc reaching the origin at t_desire,
v_d = -Phi_rv(T)^-1 Phi_rr(T) r with T = t_desire - t, tracked by g_far = k_g (v_d - v).
"""
from __future__ import annotations

import numpy as np

try:  # np.linalg.solve's own gufunc for a 1-D right-hand side (private to numpy: solve_each falls back)
    from numpy.linalg import _umath_linalg
    _SOLVE1 = getattr(_umath_linalg, "solve1", None)
except ImportError:  # pragma: no cover - another numpy layout
    _SOLVE1 = None


def cw_position_blocks(n_radps: float, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Phi_rr(t) and Phi_rv(t) of the CW state-transition matrix (r(t) = Phi_rr r0 + Phi_rv v0).

    Each entry is the float64 of the products and sums below (sin and cos by numpy; the entries'
    arithmetic on Python floats, the same IEEE operations as on numpy scalars; Phi_rv divided by
    n as one array)."""
    tau = n_radps * t_s
    s, c = float(np.sin(tau)), float(np.cos(tau))
    tau = float(tau)
    one_c = 1.0 - c
    blocks = np.array((4.0 - 3.0 * c, 0.0, 0.0, 6.0 * (s - tau), 1.0, 0.0, 0.0, 0.0, c,
                       s, 2.0 * one_c, 0.0, -2.0 * one_c, 4.0 * s - 3.0 * tau, 0.0, 0.0, 0.0, s)).reshape(2, 3, 3)
    return blocks[0], blocks[1] / n_radps


def solve_each(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """`np.linalg.solve(a, b[i])` of one (3, 3) float64 system `a` against each (3,) float64 row of
    `b` (k, 3): the gufunc `np.linalg.solve` calls for a 1-D right-hand side (LAPACK `dgesv` on each
    system alone), without the wrapper's checks and error state. A singular `a` gives NaN rows (and
    numpy's invalid-value warning) instead of raising: the caller tests the result. Where numpy has
    no such gufunc, one `np.linalg.solve` per row (the same LAPACK call; a singular `a` raises)."""
    if _SOLVE1 is not None:
        return _SOLVE1(a, b)
    return np.array([np.linalg.solve(a, row) for row in b], dtype=float).reshape(b.shape)


def matvec_rows(m: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(k, 3) `m @ rows[i]` of each row of a C-contiguous (k, 3) float64 array, each the BLAS `gemv`
    that the 1-D product calls (`np.matvec`, numpy >= 2.2, and `np.matmul` against (k, 3, 1) columns
    both call numpy's `DOUBLE_gemv` with the same strides)."""
    if _MATVEC is not None:
        return _MATVEC(m, rows)
    return np.matmul(m, rows[:, :, None])[:, :, 0]


_MATVEC = getattr(np, "matvec", None)


def ballistic_velocity(position_m: np.ndarray, n_radps: float, time_to_go_s: float) -> np.ndarray:
    """Eq. 1 (reading): the velocity on the natural CW arc from `position_m` to the origin in time_to_go_s."""
    if time_to_go_s <= 0.0:
        raise ValueError(f"time to go {time_to_go_s} s: the ballistic field is only defined before t_desire")
    phi_rr, phi_rv = cw_position_blocks(n_radps, time_to_go_s)
    return -np.linalg.solve(phi_rv, phi_rr @ np.asarray(position_m, dtype=float))


def far_accel(position_m: np.ndarray, velocity_mps: np.ndarray, n_radps: float, time_to_go_s: float,
              gain_ps: float) -> np.ndarray:
    """Eq. 2 (reading): g_far = k_g (v_d - v), m/s^2; zero once the agent is on its ballistic arc."""
    return gain_ps * (ballistic_velocity(position_m, n_radps, time_to_go_s) - np.asarray(velocity_mps, dtype=float))
