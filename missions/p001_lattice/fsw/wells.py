"""The near-layer gathering wells of paper 001 (eq. 3-5), in SI.

Each well is g = -alpha (r - r0) exp(-|r - r0|^2 / k): alpha in 1/s^2 (amplitude), k in m^2
(range; the well acts over about sqrt(k)). Table 4 gives alpha_f = 5.1676e3 / t_e^2 and
k_f = 3.9822e-10 l_e^2 (about (127 m)^2); alpha_pl, k_pl equal them; alpha_ph, k_ph are not given.
"""
from __future__ import annotations

import numpy as np


def point_well(position_m: np.ndarray, centre_m: np.ndarray, alpha_ps2: float, k_m2: float) -> np.ndarray:
    """Eq. 3 (g_free, centre r0) and eq. 5 (g_phase, centre = a dock vertex), m/s^2."""
    d = np.asarray(position_m, dtype=float) - np.asarray(centre_m, dtype=float)
    return -alpha_ps2 * d * np.exp(-float(d @ d) / k_m2)


def planar_well(position_m: np.ndarray, x_shift_m: float, alpha_ps2: float, k_m2: float) -> np.ndarray:
    """Eq. 4 (g_planar): pulls x towards the plane x = x_shift only, m/s^2."""
    dx = float(position_m[0]) - x_shift_m
    return np.array([-alpha_ps2 * dx * np.exp(-dx * dx / k_m2), 0.0, 0.0])


def damping(velocity_mps: np.ndarray, gamma_ps: float) -> np.ndarray:
    """Eq. 15: virtual viscosity d = -gamma v, m/s^2."""
    return -gamma_ps * np.asarray(velocity_mps, dtype=float)


def saturate(accel_mps2: np.ndarray, max_accel_mps2: float) -> np.ndarray:
    """Thrust limit u_max (Table 2) applied to the norm, keeping the direction."""
    a = np.asarray(accel_mps2, dtype=float)
    norm = float(np.linalg.norm(a))
    return a if norm <= max_accel_mps2 else a * (max_accel_mps2 / norm)
