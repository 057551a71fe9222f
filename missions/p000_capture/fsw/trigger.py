"""The event trigger for the chase PD and the state broadcast (paper 000 eq. 26–29)."""
from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from .limits import dot3, dot_rows, norm3


@dataclass(frozen=True)
class TriggerSettings:
    c0: float = 0.05
    c1: float = 0.2499
    beta_per_s: float = 0.1
    c_d: float = 1.0


def cw_disturbance_bound(position_m: np.ndarray, velocity_mps: np.ndarray, n_radps: float) -> float:
    """d_max = 3n²‖r‖ + 2n‖v‖ (§2.1.1, after eq. 8): the CW coupling bound used in eq. 28."""
    return 3.0 * n_radps ** 2 * norm3(position_m) + 2.0 * n_radps * norm3(velocity_mps)


def threshold(t_s: float, d_max: float, s: TriggerSettings) -> float:
    """c0 + c1 e^(−βt) + c_d d_max (eq. 28), t the global time as written."""
    return s.c0 + s.c1 * math.exp(-s.beta_per_s * t_s) + s.c_d * d_max


def sample_error(r_k: np.ndarray, v_k: np.ndarray, r: np.ndarray, v: np.ndarray) -> float:
    """‖[P; V]‖ with P = r(t_k) − r(t), V = v(t_k) − v(t) (eq. 27–28)."""
    p, v_err = r_k - r, v_k - v
    return math.sqrt(dot3(p, p) + dot3(v_err, v_err))


def fires(t_s: float, r_k: np.ndarray, v_k: np.ndarray, r: np.ndarray, v: np.ndarray,
          d_max: float, s: TriggerSettings) -> bool:
    """f_i > 0 (eq. 27, 29)."""
    return sample_error(r_k, v_k, r, v) > threshold(t_s, d_max, s)


def fires_rows(t_s: float, r_k: np.ndarray, v_k: np.ndarray, r: np.ndarray, v: np.ndarray, n_radps: float,
               s: TriggerSettings) -> np.ndarray:
    """`fires(t, r_k, v_k, r, v, cw_disturbance_bound(r, v, n), s)` of N agents' rows at once, row i
    the same answer from the same bits: eq. 27-29 written out over arrays in the scalar code's
    order (the norms' dots as `dot3`'s, Python's n² and e^(−βt) once)."""
    d_max = 3.0 * n_radps ** 2 * np.sqrt(dot_rows(r, r)) + 2.0 * n_radps * np.sqrt(dot_rows(v, v))
    p, v_err = r_k - r, v_k - v
    return np.sqrt(dot_rows(p, p) + dot_rows(v_err, v_err)) > s.c0 + s.c1 * math.exp(-s.beta_per_s * t_s) + s.c_d * d_max
