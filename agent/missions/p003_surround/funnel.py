"""Leader target tracking: performance functions, arctan funnel transformation and TT control
(eq. 15-17), signs restored.

q~_TL = q_TL - q_TL,d is the target's position relative to the leader minus its desired value
(leader LVLH). The bounds are |q~_TL,l| < tan(k1(t) π/2): infinite at t = 0 (k1(0) = 1),
"initial-condition-free" (Remark 6). u_L is the *relative* control of the proof
(q''_TL = u_L/m_L + h), so the leader's physical thrust is -u_L (NOTES-003).
"""
from __future__ import annotations

import numpy as np

from agent.missions.p003_surround.params import FunnelParams


def performance(t_s: float, mu: float, a_per_s: float) -> float:
    """k_r(t) = (1 - μ_r) exp(-a_r t) + μ_r (after eq. 15)."""
    return (1.0 - mu) * float(np.exp(-a_per_s * t_s)) + mu


def funnel_half_width(t_s: float, mu: float, a_per_s: float) -> float:
    """The bound tan(k_r(t) π/2) of Remark 6 (inf at t = 0)."""
    k = performance(t_s, mu, a_per_s)
    return float(np.inf) if k >= 1.0 else float(np.tan(k * np.pi / 2.0))


def transformed_error(err: np.ndarray, k: float) -> np.ndarray:
    """e = arctan(err) / k (eq. 15; its inverse is eq. 32-33: err = tan(k e))."""
    return np.arctan(np.asarray(err, dtype=float)) / k


def _tan_inside(e: np.ndarray) -> np.ndarray:
    """tan(e), with e held just inside (-π/2, π/2) where the funnel has been left (guard)."""
    lim = np.pi / 2.0 - 1e-9
    return np.tan(np.clip(e, -lim, lim))


def virtual_velocity(q_tl_m: np.ndarray, t_s: float, p: FunnelParams) -> tuple[np.ndarray, np.ndarray]:
    """(q'_TL^v, e1): q'_TL^v = -λ1 tan(e1) (eq. 16)."""
    e1 = transformed_error(q_tl_m - np.asarray(p.q_des_m), performance(t_s, p.mu1, p.a1_per_s))
    return -p.lambda1 * _tan_inside(e1), e1


def tt_control(q_tl_m: np.ndarray, v_tl_mps: np.ndarray, t_s: float,
               p: FunnelParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u_L in N, e1, e2): u_L = -λ2 tan(e2), e2 = arctan(q'_TL - q'_TL^v)/k2 (eq. 15, 17).

    u_L is the relative control (q''_TL = u_L/m_L + h), unsaturated; see `leader_thrust`.
    """
    v_virtual, e1 = virtual_velocity(q_tl_m, t_s, p)
    e2 = transformed_error(np.asarray(v_tl_mps) - v_virtual, performance(t_s, p.mu2, p.a2_per_s))
    return -p.lambda2 * _tan_inside(e2), e1, e2


def clip_norm(vec: np.ndarray, limit: float) -> np.ndarray:
    """vec scaled down to Euclidean norm `limit` if it is longer."""
    norm = float(np.linalg.norm(vec))
    return vec if norm <= limit else vec * (limit / norm)


def leader_accel(u_l_n: np.ndarray, p: FunnelParams) -> np.ndarray:
    """The leader's physical acceleration in m/s^2: -u_L/m_L with |u_L| <= u_L,max (180 N)."""
    return -clip_norm(np.asarray(u_l_n, dtype=float), p.max_thrust_n) / p.mass_kg
