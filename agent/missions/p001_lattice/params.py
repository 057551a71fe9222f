"""The paper's Tables 2-4 in SI, with the readings of the open items as named options.

Built from the scenario's `[controller]` table by `LatticeParams.from_dict`; every field has the
paper's value (or this room's stated choice where the paper is silent) as its default.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from agent.missions.p001_lattice.tersoff import CUTOFF_READINGS
from agent.missions.p001_lattice.units import (
    A_E_MPS2,
    EARTH_RATE_RADPS,
    area_from_normalised,
    rate_from_normalised,
    stiffness_from_normalised,
)

TB_UNITS = ("mps2", "a_e")

ALPHA_F_PS2 = stiffness_from_normalised(5.1676e3)  # Table 4, ~2.75e-5 1/s^2
K_F_M2 = area_from_normalised(3.9822e-10)  # Table 4, ~(127.3 m)^2
GAMMA_PS = rate_from_normalised(2.4027e2)  # Table 4, ~1.75e-2 1/s


@dataclass(frozen=True)
class LatticeParams:
    # Table 2
    mean_motion_radps: float = EARTH_RATE_RADPS
    side_m: float = 10.0  # l
    sensing_radius_m: float = 21.0  # r_Z (applied by the plant; kept here to state it)
    max_accel_mps2: float = 5e-3  # u_max
    t_desire_s: float = 1.95e4
    t_natural_s: float = 0.975 * 1.95e4
    r_outer_m: float = 1000.0
    r_middle_m: float = 100.0
    r_inner_m: float = 15.0
    x_shift_m: float = 0.0
    phase_deg: float = 30.0  # Fig. 1: vertex angles from +y in the yz-plane, 30 + 60 k
    # Table 4
    alpha_free_ps2: float = ALPHA_F_PS2
    k_free_m2: float = K_F_M2
    alpha_planar_ps2: float = ALPHA_F_PS2
    k_planar_m2: float = K_F_M2
    damping_ps: float = GAMMA_PS
    # open items (NOTES-001), named readings
    alpha_phase_ps2: float = ALPHA_F_PS2  # not in Table 4: alpha_ph = alpha_f
    k_phase_m2: float = K_F_M2  # not in Table 4: k_ph = k_f (a ~127 m wide dock well)
    free_in_shaping: bool = False  # Table 3: g_free off in the shaping ball
    cutoff_reading: str = "normalised"  # R(1), R(2) divided by 1.315 (or "literal")
    tb_unit: str = "mps2"  # eq. 14 output read in m/s^2 (or "a_e")
    far_gain_ps: float = 0.05  # k_g, not given
    far_damping: bool = False  # Table 3: no dissipation in the natural gathering layer

    def __post_init__(self) -> None:
        if self.cutoff_reading not in CUTOFF_READINGS:
            raise ValueError(f"cutoff_reading {self.cutoff_reading!r} not in {CUTOFF_READINGS}")
        if self.tb_unit not in TB_UNITS:
            raise ValueError(f"tb_unit {self.tb_unit!r} not in {TB_UNITS}")
        if not self.r_outer_m > self.r_middle_m > self.r_inner_m > 0.0:
            raise ValueError(f"need r_outer > r_middle > r_inner > 0, got {self.r_outer_m}, {self.r_middle_m}, {self.r_inner_m}")
        if not 0.0 < self.t_natural_s < self.t_desire_s:
            raise ValueError(f"need 0 < t_natural < t_desire, got {self.t_natural_s}, {self.t_desire_s}")

    @property
    def tb_accel_unit_mps2(self) -> float:
        """What one unit of eq. 14's output is in m/s^2 under the chosen reading."""
        return 1.0 if self.tb_unit == "mps2" else A_E_MPS2

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> "LatticeParams":
        known = {f.name: f for f in fields(cls)}
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise ValueError(f"unknown p001-lattice parameters {unknown}; known: {sorted(known)}")
        defaults = cls()
        values = {}
        for k, v in params.items():
            kind = type(getattr(defaults, k))
            if kind is bool and not isinstance(v, bool):
                raise ValueError(f"p001-lattice parameter {k} must be true or false, got {v!r}")
            values[k] = kind(v)
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
