"""Leader target tracking: performance functions, arctan funnel transformation and TT control
(eq. 15-17), signs restored.

q~_TL = q_TL - q_TL,d is the target's position relative to the leader minus its desired value
(leader LVLH). The bounds are |q~_TL,l| < tan(k1(t) π/2): infinite at t = 0 (k1(0) = 1),
"initial-condition-free" (Remark 6). u_L is the *relative* control of the proof
(q''_TL = u_L/m_L + h), so the leader's physical thrust is -u_L (NOTES-003).

Discrete-time guard (`sampled_limit`): the laws are continuous-time and singular at the bound;
a flight computer holds each output over one sample. Each transformed error is saturated at the
largest e* short of π/2 at which the held output cannot carry its error past zero within the sample
(docs/paper003.md, "The funnel in discrete time").
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.agent.rowwise import row_dots
from swarmhil.missions.p003_surround.contract import FunnelParams, performance, transformed_error


def sampled_limit(k: float, gain_hold: float) -> float:
    """e* in (0, π/2]: the saturation of the transformed error e = arctan(x)/k (eq. 15) for a law
    y = -λ tan(e) (eq. 16-17) whose output is held over a sample of length T.

    `gain_hold` is g = λT in units of the error: λ1 T for eq. 16 (q~' = -λ1 tan e1 once the
    velocity follows), λ2 T/m_L for eq. 17 (q~'' = u_L/m_L). One held sample changes the error x by
    -g tan(e), and tan(e)/x = tan(e)/tan(k e) grows without bound as e -> π/2 (the funnel's
    singular gain). e* is the largest e with g tan(e) <= tan(k e): below it one sample moves x at
    most to 0; clipping e at e* caps the sampled gain there, and bounds the output beyond the funnel
    (y = -λ tan e*, about the error x* = tan(k e*) in one sample) instead of -λ tan(π/2 - ε).
    Solved as s = π/2 - e*, tan(s) = g tan(c + k s), c = (1 - k) π/2, by fixed-point iteration from
    s = 0 (a contraction for 0 < g < 1 and k >= μ; 8 iterations at the 0.1 s step, 35 at g = 0.3).
    At k = 1 (t = 0, the funnel infinite) e* = π/2: the law is linear there and no guard is needed.
    """
    if not 0.0 < gain_hold < 1.0:
        raise ValueError(f"sampled gain λT must be in (0, 1) for the held law not to overshoot, got {gain_hold}")
    c = (1.0 - k) * math.pi / 2.0
    s = 0.0
    for _ in range(60):
        s_next = math.atan(gain_hold * math.tan(c + k * s))
        if s_next == s:
            break
        s = s_next
    return math.pi / 2.0 - s


def tan_sampled(e: np.ndarray, k: float, gain_hold: float) -> np.ndarray:
    """tan(e) with e clipped to ±e* = ±sampled_limit(k, g) (the discrete-time guard of eq. 16-17)."""
    lim = sampled_limit(k, gain_hold)
    return np.tan(np.clip(e, -lim, lim))


def virtual_velocity(q_tl_m: np.ndarray, t_s: float, p: FunnelParams,
                     hold_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(q'_TL^v, e1): q'_TL^v = -λ1 tan(e1) (eq. 16), e1 saturated at e* for the hold T
    (`hold_s`, default `p.sample_s`) with g = λ1 T."""
    k1 = performance(t_s, p.mu1, p.a1_per_s)
    e1 = transformed_error(q_tl_m - np.asarray(p.q_des_m), k1)
    hold = p.sample_s if hold_s is None else hold_s
    return -p.lambda1 * tan_sampled(e1, k1, p.lambda1 * hold), e1


def tt_control(q_tl_m: np.ndarray, v_tl_mps: np.ndarray, t_s: float,
               p: FunnelParams, hold_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u_L in N, e1, e2): u_L = -λ2 tan(e2), e2 = arctan(q'_TL - q'_TL^v)/k2 (eq. 15, 17).

    Both transformed errors are saturated at their `sampled_limit` for the hold T (`hold_s`,
    default `p.sample_s`): g = λ1 T for e1, λ2 T/m_L for e2. e1 and e2 are returned unsaturated.
    u_L is the relative control (q''_TL = u_L/m_L + h), unsaturated in thrust; see `leader_accel`.
    """
    hold = p.sample_s if hold_s is None else hold_s
    v_virtual, e1 = virtual_velocity(q_tl_m, t_s, p, hold)
    k2 = performance(t_s, p.mu2, p.a2_per_s)
    e2 = transformed_error(np.asarray(v_tl_mps) - v_virtual, k2)
    return -p.lambda2 * tan_sampled(e2, k2, p.lambda2 * hold / p.mass_kg), e1, e2


def clip_norm(vec: np.ndarray, limit: float) -> np.ndarray:
    """vec scaled down to Euclidean norm `limit` if it is longer."""
    v = vec.ravel(order="K") if isinstance(vec, np.ndarray) and vec.dtype == np.float64 else None
    # np.linalg.norm of a float64 array is sqrt(v . v) (its ravel, dot and sqrt) without its Python (issue 29)
    norm = math.sqrt(v.dot(v)) if v is not None else float(np.linalg.norm(vec))
    return vec if norm <= limit else vec * (limit / norm)


def clip_norm_rows(vecs: np.ndarray, limit: float) -> np.ndarray:
    """Each row of `vecs` (S, 3) as `clip_norm` gives it, as a new array: the same norm per row
    (sqrt of the row's dot with itself: `row_dots`, BLAS's `ddot` per row, the product `clip_norm`
    and np.linalg.norm take) and the same scaling (the rows not under the limit, NaN norms
    included, times limit / norm)."""
    v = np.asarray(vecs, dtype=float).reshape(-1, 3)
    norm = np.sqrt(row_dots(v))
    out = v.copy()
    over = ~(norm <= limit)
    if over.any():
        out[over] = v[over] * (limit / norm[over])[:, None]
    return out


def leader_accel(u_l_n: np.ndarray, p: FunnelParams) -> np.ndarray:
    """The leader's physical acceleration in m/s^2: -u_L/m_L with |u_L| <= u_L,max (180 N)."""
    return -clip_norm(np.asarray(u_l_n, dtype=float), p.max_thrust_n) / p.mass_kg
