"""Approximate Nash CT controllers of the nonzero-sum game with the immersed variable ξ
(eq. 12, 18-21), for N servicers, over stacked arrays.

x~ (N, 6): CT errors [q~_Li, q~'_Li] in the leader's LVLH; ξ (N, 6) the immersion variable.
P_i(ξ) is zero except block i = (ϑ_i(ξ) + γ) I_6 with ϑ_i = κ + α_F c_FC,i + α_Cg c_Cg,i (eq. 19),
the threats evaluated at the positions ξ_i[:3] + q_Li,d; R_i = r_weight * diag{0, I(i), 0} (§5).

V_i(x~, ξ) = ½ x~^T P_i(ξ) x~ + ½ (x~ - ξ)^T R_i (x~ - ξ)                          (eq. 18)
ξ' = -η Σ_i (∂V_i/∂ξ)^T                                                            (eq. 20)
u_ci = -B_hat_i^T H^-1 (∂V_i/∂x~)^T, with B_hat_i^T H^-1 -> [k_pos I, k_vel I]   (eq. 21, choice)
"""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p003_surround.contract import GameParams
from swarmhil.missions.p003_surround.fsw.threat import (
    pair_threat_grads,
    pair_threats,
    structure_threat,
    structure_threat_grad,
)


def theta(xi: np.ndarray, slots_m: np.ndarray, centres_m: np.ndarray, radii_m: np.ndarray,
          g: GameParams) -> np.ndarray:
    """ϑ_i(ξ) = κ + α_F c_FC,i + α_Cg c_Cg,i (eq. 12, 19) for every servicer, (N,)."""
    pos = xi[:, :3] + slots_m
    r = np.full(len(pos), g.safe_radius_m)
    c_fc = pair_threats(pos, r, g.h_fc, g.barrier_floor_m2)
    c_cg = structure_threat(pos, centres_m, radii_m, g.safe_radius_m, g.h_cg, g.barrier_floor_m2)
    return g.kappa + g.alpha_fc * c_fc + g.alpha_cg * c_cg


def values(x_err: np.ndarray, xi: np.ndarray, slots_m: np.ndarray, centres_m: np.ndarray,
           radii_m: np.ndarray, g: GameParams) -> np.ndarray:
    """V_i(x~, ξ) of eq. 18 for every servicer, (N,)."""
    th = theta(xi, slots_m, centres_m, radii_m, g)
    quad = np.einsum("ij,ij->i", x_err, x_err)
    dev = x_err - xi
    return 0.5 * (th + g.gamma) * quad + 0.5 * g.r_weight * np.einsum("ij,ij->i", dev, dev)


def value_grad_x(x_err: np.ndarray, xi: np.ndarray, slots_m: np.ndarray, centres_m: np.ndarray,
                 radii_m: np.ndarray, g: GameParams) -> np.ndarray:
    """Row i: ∂V_i/∂x~_i = (ϑ_i(ξ) + γ) x~_i + r_weight (x~_i - ξ_i), (N, 6)."""
    th = theta(xi, slots_m, centres_m, radii_m, g)
    return (th + g.gamma)[:, None] * x_err + g.r_weight * (x_err - xi)


def xi_rate(x_err: np.ndarray, xi: np.ndarray, slots_m: np.ndarray, centres_m: np.ndarray,
            radii_m: np.ndarray, g: GameParams) -> np.ndarray:
    """ξ' = -η ∂(Σ_k V_k)/∂ξ (eq. 20), (N, 6).

    With w_k = ½|x~_k|^2: ∂ΣV/∂ξ_i[:3] = α_F Σ_j (w_i + w_j) ∇φ(p_i - p_j)
    + α_Cg w_i ∂c_Cg,i/∂p_i - r_weight (x~_i - ξ_i)[:3]; the velocity part is the R term only.
    """
    pos = xi[:, :3] + slots_m
    w = 0.5 * np.einsum("ij,ij->i", x_err, x_err)
    r = np.full(len(pos), g.safe_radius_m)
    pair = pair_threat_grads(pos, r, g.h_fc, g.barrier_floor_m2)
    grad = -g.r_weight * (x_err - xi)
    grad[:, :3] += g.alpha_fc * np.einsum("ij,ijk->ik", w[:, None] + w[None, :], pair)
    grad[:, :3] += g.alpha_cg * w[:, None] * structure_threat_grad(
        pos, centres_m, radii_m, g.safe_radius_m, g.h_cg, g.barrier_floor_m2)
    return -g.eta * grad


def ct_accel(grad_x: np.ndarray, g: GameParams) -> np.ndarray:
    """u_ci*/m_i = -(k_pos ∂V_i/∂q~_i + k_vel ∂V_i/∂q~'_i) (eq. 21 with the chosen ΔB_i), (..., 3)."""
    return -(g.k_pos_per_s2 * grad_x[..., :3] + g.k_vel_per_s * grad_x[..., 3:])


def linear_ct_matrix(g: GameParams) -> np.ndarray:
    """Per-axis linearisation of the CT loop with ξ far from every threat (ϑ = κ), state
    (q~, q~', ξ_q, ξ_v): q~'' = -k_pos((κ+γ+ρ) q~ - ρ ξ_q) - k_vel((κ+γ+ρ) q~' - ρ ξ_v),
    ξ' = η ρ (x~ - ξ) (eq. 20-21 with u_id cancelling the natural motion), (4, 4)."""
    c, rho = g.kappa + g.gamma + g.r_weight, g.r_weight
    return np.array([
        [0.0, 1.0, 0.0, 0.0],
        [-g.k_pos_per_s2 * c, -g.k_vel_per_s * c, g.k_pos_per_s2 * rho, g.k_vel_per_s * rho],
        [g.eta * rho, 0.0, -g.eta * rho, 0.0],
        [0.0, g.eta * rho, 0.0, -g.eta * rho],
    ])


def slow_mode_rate(g: GameParams) -> float:
    """Slowest decay rate (1/s) of `linear_ct_matrix`: ≈ η ρ (κ+γ)/(κ+γ+ρ) <= η (κ+γ) when the CT
    loop is fast (NOTES-003)."""
    return float(-np.max(np.linalg.eigvals(linear_ct_matrix(g)).real))


def slow_mode_rate_approx(g: GameParams) -> float:
    """η ρ (κ+γ)/(κ+γ+ρ): the rate when x~ sits at its quasi-static equilibrium ρ ξ/(κ+γ+ρ)."""
    k = g.kappa + g.gamma
    return g.eta * g.r_weight * k / (k + g.r_weight)
