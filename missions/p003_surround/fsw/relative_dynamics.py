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
    grav = -mu * r / np.linalg.norm(r, axis=-1, keepdims=True) ** 3 + mu * r_ref / a_m**3
    coriolis = np.stack([2 * n_radps * v[..., 1], -2 * n_radps * v[..., 0], np.zeros_like(v[..., 2])], -1)
    centrifugal = np.stack([n_radps**2 * q[..., 0], n_radps**2 * q[..., 1], np.zeros_like(q[..., 2])], -1)
    return grav + coriolis + centrifugal
