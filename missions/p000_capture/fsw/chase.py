"""Chase PD toward the buffer slot (paper 000 eq. 14, 25–26) and its approach governor."""
from __future__ import annotations

import numpy as np

from .limits import norm3


def chase_force(r_m: np.ndarray, v_mps: np.ndarray, slot_m: np.ndarray, slot_v_mps: np.ndarray,
                k_p: float, k_v: float, max_error_m: float | None) -> np.ndarray:
    """F = −K_p (r − r_T) − K_v (v − v_T) (eq. 25); with `max_error_m` the position error is
    clipped to that norm first, which caps the approach speed at K_p e_max / K_v (NOTES-000
    trap 1: the literal law brakes too late under F_max and flies agents through the target)."""
    e = np.asarray(r_m, dtype=float) - slot_m
    if max_error_m is not None:
        n = norm3(e)
        if n > max_error_m:
            e = e * (max_error_m / n)
    return -k_p * e - k_v * (np.asarray(v_mps, dtype=float) - slot_v_mps)
