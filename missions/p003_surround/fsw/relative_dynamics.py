"""Natural relative motion in the leader's LVLH, cancelled by the servicers' u_id (eq. 6).

The flight software knows the reference orbit only as `OrbitInfo` (a, n): it models the leader on
a circular orbit of radius a with rate n (x radial, y along-track, z orbit normal), and computes
q'' = -2 ω×q' - ω×(ω×q) + g(R_L + q) - g(R_L), g(r) = -μ r/|r|^3, μ = n^2 a^3  (eq. 3-5's
C_hat_ω q' + N(q) for a circular reference). The leader's own thrust is covered by u_Li.
"""
from __future__ import annotations

import numpy as np


def natural_rel_accel(q_m: np.ndarray, v_mps: np.ndarray, a_m: float, n_radps: float) -> np.ndarray:
    """Unforced relative acceleration of a body at (q, q') in a circular reference's LVLH, (..., 3)."""
    q = np.asarray(q_m, dtype=float)
    v = np.asarray(v_mps, dtype=float)
    mu = n_radps**2 * a_m**3
    r_ref = np.array([a_m, 0.0, 0.0])
    r = r_ref + q
    # np.linalg.norm's |r| and np.stack's rows, without their Python (the same values; issue 29)
    grav = -mu * r / np.sqrt(np.add.reduce(r * r, axis=-1, keepdims=True)) ** 3 + mu * r_ref / a_m**3
    coriolis, centrifugal = np.empty(np.shape(v)), np.empty(np.shape(q))
    coriolis[..., 0], coriolis[..., 1], coriolis[..., 2] = 2 * n_radps * v[..., 1], -2 * n_radps * v[..., 0], 0.0
    centrifugal[..., 0], centrifugal[..., 1], centrifugal[..., 2] = n_radps**2 * q[..., 0], n_radps**2 * q[..., 1], 0.0
    return grav + coriolis + centrifugal
