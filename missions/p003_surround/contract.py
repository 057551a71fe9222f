"""Paper 003's contract: what the plant's sensing kind, the flight software and the report share.

Imports nothing of the project but `bus` (here: nothing at all); numpy only. Read by
missions/p003_surround/sense.py (the sensor `p003-relative`), missions/p003_surround/fsw/ (the
leader's and the servicers' flight software) and the paper's report (missions/p003_surround/report.py).
docs/architecture.md "Mission rooms (issue 25)".

**Names.** `LEADER_CONTROLLER`, `SERVICER_CONTROLLER` are the names the flight software registers
and the report looks for. The measurements arrive in `Observation.extra` as named arrays
(bus/codec.py add_measurement, "<name>/<subject>"), in the leader's LVLH:

    leader:    "p003.target_rel.position_m", "p003.target_rel.velocity_mps"  (subject: target id)
    servicer:  "p003.leader_rel.position_m", "p003.leader_rel.velocity_mps"  (subject: leader id)

**Parameter models** (§5 values and the readings of what the paper leaves open, frozen typed
configuration): every number the paper gives is a default here with its source; every number it
does not give is marked "choice" and discussed in docs/paper003.md. Frame: the leader's LVLH
(x radial outward, y along-track, z orbit normal), positions in m, velocities in m/s,
accelerations in m/s^2. `servicer_index` tells a servicer's slot (Table 1 row).

**Structure** (Table 1-2): the target's ACSB envelope (signs and square roots restored) and the
servicers' slots. NOTES-003: the extracted Table 2 lost its minus signs and its √ ("15 2" is 15√2 m).
The structure is symmetric: the core cabin along +x, the transporter along -x, payload cabins I and
II at +y and -y, solar arrays I and II at +z and -z. Centres d_Cg are in the target's frame
(attitude ignored, Assumption 2), so q_Cg(t) = q_TL(t) + d_Cg in the leader's LVLH (§5).

**Funnel geometry** (eq. 15, Remark 6): the performance functions, the bound and the transformed
error, which the leader's TT control (fsw/funnel.py) and the report both evaluate.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

LEADER_CONTROLLER = "p003-leader"
SERVICER_CONTROLLER = "p003-servicer"
TARGET_REL_KEY = "p003.target_rel"
"""Leader: the target relative to the leader, q_TL = r_T - r_L and q'_TL (Assumption 1)."""
LEADER_REL_KEY = "p003.leader_rel"
"""Servicer i: itself relative to the leader, q_Li = r_i - r_L and q'_Li."""

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


SQRT2 = float(np.sqrt(2.0))


@dataclass(frozen=True)
class Sphere:
    part: str
    centre_m: tuple[float, float, float]
    radius_m: float


def _spheres() -> tuple[Sphere, ...]:
    rows: list[Sphere] = [Sphere("core cabin", (0.0, 0.0, 0.0), 5 * SQRT2)]
    rows += [Sphere("core cabin", (x, 0.0, 0.0), 15 * SQRT2) for x in (20.0, 50.0, 80.0)]
    rows += [Sphere("transporter", (-x, 0.0, 0.0), 10 * SQRT2) for x in (15.0, 35.0, 55.0)]
    for name, sign in (("payload cabin I", 1.0), ("payload cabin II", -1.0)):
        rows.append(Sphere(name, (0.0, sign * 10.0, 0.0), 5 * SQRT2))
        rows += [Sphere(name, (0.0, sign * y, 0.0), 10 * SQRT2) for y in (25.0, 45.0)]
    for name, sign in (("solar array I", 1.0), ("solar array II", -1.0)):
        rows += [Sphere(name, (0.0, 0.0, sign * z), 5 * SQRT2) for z in (10.0, 20.0, 30.0, 40.0)]
    return tuple(rows)


ACSB_SPHERES: tuple[Sphere, ...] = _spheres()
"""Table 2: 21 circumscribed spheres (d_Cg, r_g)."""


def sphere_arrays(spheres: tuple[Sphere, ...] = ACSB_SPHERES) -> tuple[np.ndarray, np.ndarray]:
    """(G, 3) centres d_Cg and (G,) radii r_g, in m."""
    return (np.array([s.centre_m for s in spheres], dtype=float),
            np.array([s.radius_m for s in spheres], dtype=float))


SLOT_OFFSETS_M: np.ndarray = np.array([
    [50.0, 50.0, -50.0],
    [50.0, -50.0, 50.0],
    [-50.0, 50.0, 50.0],
    [50.0, -50.0, -50.0],
    [-50.0, 50.0, -50.0],
    [-50.0, -50.0, 50.0],
])
"""Table 1's desired q_Ti,d, all printed (50, 50, 50): corners (±50, ±50, ±50) of the target.
Choice: the six corners off the approach diagonal (+,+,+)/(-,-,-) along which the target comes in
from q_TL(0) = (900, 500, 500) m, so the target's own approach never sweeps through a slot."""


def slots_in_leader_frame(q_tl_des_m: np.ndarray, offsets_m: np.ndarray = SLOT_OFFSETS_M) -> np.ndarray:
    """Desired q_Li,d = q_TL,d + q_Ti,d (eq. 1 with q_TL the target relative to the leader), (N, 3)."""
    return np.asarray(q_tl_des_m, dtype=float)[None, :] + np.asarray(offsets_m, dtype=float)


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


def servicer_index(sc_id: str, params: dict[str, Any]) -> int:
    """`params["index"]` if given, else the trailing digits of the id minus one ("ssat3" -> 2)."""
    if "index" in params:
        return int(params["index"])
    digits = "".join(ch for ch in sc_id if ch.isdigit())
    if not digits:
        raise ValueError(f"cannot tell the servicer index of {sc_id!r}: give params['index']")
    return int(digits) - 1
