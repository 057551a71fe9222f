"""Paper 003's §5 values and the readings of what it leaves open, as frozen typed configuration.

Every number the paper gives is a default here with its source; every number it does not give is
marked "choice" and discussed in docs/paper003.md. Frame: the leader's LVLH (x radial outward,
y along-track, z orbit normal), positions in m, velocities in m/s, accelerations in m/s^2.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np


@dataclass(frozen=True)
class FunnelParams:
    """Leader target-tracking (TT) controller, eq. 15-17 and §5."""

    mu1: float = 0.1
    mu2: float = 0.1
    a1_per_s: float = 5e-5  # §5 prints "5 x 10 5": the minus sign is lost (NOTES-003)
    a2_per_s: float = 5e-4  # §5 prints "5 x 10 4"
    lambda1: float = 0.02
    lambda2: float = 4.5  # N per unit tan(e2): u_L is a force (eq. 17, q''_TL = u_L/m_L + h)
    q_des_m: tuple[float, float, float] = (400.0, 0.0, 0.0)  # q_TL,d (§5)
    mass_kg: float = 60.0  # m_L (§5)
    max_thrust_n: float = 180.0  # u_L,max (§5); choice: limit on the Euclidean norm
    # guard: the period T over which u_L is held (§5's step), for the discrete-time saturation of
    # e1, e2 (funnel.sampled_limit); the leader uses the measured interval between its steps
    sample_s: float = 0.1


@dataclass(frozen=True)
class GameParams:
    """Servicer configuration-tracking (CT) Nash controllers, eq. 7-8, 12, 18-21 and §5."""

    kappa: float = 0.08
    gamma: float = 8e-4
    alpha_fc: float = 1e-3  # α_F (§5)
    alpha_cg: float = 1e-3  # choice: α_Cg is not given apart from α_F
    h_fc: float = 1.0
    h_cg: float = 1.0
    eta: float = 0.04
    r_weight: float = 1.0  # R_i = r_weight * diag{0, I(i), 0} (§5: r_weight = 1)
    # choice: the map B_hat_i^T H^-1 from dV_i/dx~ to acceleration (ΔB_i of Definition 3 is open):
    # accel = -(k_pos * dV/dq~ + k_vel * dV/dq~dot), in 1/s^2 and 1/s.
    k_pos_per_s2: float = 0.00926
    k_vel_per_s: float = 0.185
    mass_kg: float = 50.0  # m_i (§5)
    max_thrust_n: float = 20.0  # u_i,max (§5); choice: limit on the Euclidean norm
    safe_radius_m: float = 5.0  # r_i (§5)
    saturate: str = "sum"  # choice: "sum" limits u_Li + u_ci + u_id, "ct" limits u_ci + u_id only
    cancel_natural: bool = True  # u_id: cancel the natural relative dynamics (circular reference)
    barrier_floor_m2: float = 1e-3  # guard: d^2 - R^2 is floored here inside a sphere
    xi_rate_cap_mps: float = 10.0  # guard: |dξ/dt| (position part) is capped for the explicit update

    def __post_init__(self) -> None:
        if self.saturate not in ("sum", "ct"):
            raise ValueError(f"saturate must be 'sum' or 'ct', got {self.saturate!r}")


def from_dict(cls: type, values: dict[str, Any] | None) -> Any:
    """Build a params dataclass from scenario values, rejecting unknown keys."""
    values = dict(values or {})
    known = {f.name for f in fields(cls)}
    unknown = set(values) - known
    if unknown:
        raise ValueError(f"unknown {cls.__name__} keys {sorted(unknown)}; known: {sorted(known)}")
    if "q_des_m" in values:
        values["q_des_m"] = tuple(float(v) for v in values["q_des_m"])
    return replace(cls(), **values)


def q_des(params: FunnelParams) -> np.ndarray:
    return np.asarray(params.q_des_m, dtype=float)


VARIANT_FAST_CT: dict[str, float] = {"kappa": 1.0, "eta": 0.2, "k_pos_per_s2": 0.005, "k_vel_per_s": 0.1}
"""Stated variant (docs/paper003.md): κ = 1 and η = 0.2 move the slow mode of ξ from
η(κ+γ)ρ/(κ+γ+ρ) = 0.0030/s (τ = 334 s, the §5 weights) to 0.10/s; k_pos, k_vel are halved so that
the CT loop keeps ω_n = 0.1 rad/s with the stiffness κ+γ+ρ ≈ 2 instead of ≈ 1.08."""
