"""The flight software's own ellipsoid geometry: closest surface point and buffer slot (eq. 14).

The ellipsoid itself, the closest-point solve, the signed distance and the landmark set are shared
with the plant and live in the room's contract (missions/p000_capture/contract.py). The buffer slot
is the closest surface point pushed out along the outward normal (paper 000 eq. 14).
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.missions.p000_capture.contract import Ellipsoid, closest_point_principal, dot3


def closest_point(ell: Ellipsoid, p_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest surface point x_s and outward unit normal n at it, in LVLH (eq. 14's x_s,i, n_i)."""
    local = ell.rotation.T @ (np.asarray(p_m, dtype=float) - ell.centre_m)
    x = closest_point_principal(local, ell.semi_axes_m)
    n = x / ell.semi_axes_m ** 2
    n = n / math.sqrt(dot3(n, n))
    return ell.centre_m + ell.rotation @ x, ell.rotation @ n


def buffer_slot(ell: Ellipsoid, p_m: np.ndarray, r_buffer_m: float) -> np.ndarray:
    """x_g = x_s + R_buffer n (eq. 14): the agent's slot on the buffer shell."""
    x_s, n = closest_point(ell, p_m)
    return x_s + r_buffer_m * n
