"""The mission's numbers: paper 000 Table 1 and §4, plus the choices the paper leaves open."""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np


@dataclass(frozen=True)
class CaptureParams:
    # Table 1 / §4
    mass_kg: float = 10.0
    force_max_n: float = 0.1
    torque_max_nm: float = 0.01
    fov_full_deg: float = 75.0
    k_q: float = 1.8
    k_w: float = 0.25
    k_p: float = 0.5
    k_v: float = 1.2
    k_r: float = 8.0
    k_r_target: float = 0.4
    r_buffer_m: float = 1.0
    r_c_m: float = 9.5
    r_h_m: float = 5.5
    r_l_m: float = 8.5
    f_thr_n: float = 0.1
    # chosen (docs/paper000.md)
    inertia_kgm2: float = 0.075          # diagonal, 8U CubeSat of 10 kg
    search_box_m: float = 15.0           # S of eq. 10: [−15, 15]³
    random_alpha: float = 0.1            # F_rnd = α F_thr, random unit direction
    random_redraw_s: float = 10.0
    buffer_damping_nspm: float = 1.0
    search_attitude: str = "scan"        # "scan" (spin about body z) | "hold" (rate damping only)
    scan_rate_dps: float = 2.0
    chase_law: str = "governed"          # "literal" (eq. 25–26) | "governed" (error clipped)
    approach_speed_mps: float = 0.08     # governed: ‖e‖ clipped at v K_v / K_p
    broadcast: str = "event"             # "event" (eq. 28) | "every-step" | "periodic"
    broadcast_period_s: float = 1.0
    perception_period_s: float = 1.0
    detect_min_returns: int = 8
    fit_min_points: int = 30
    fit_max_points: int = 200
    track_min_inlier_fraction: float = 0.6
    estimate_max_age_s: float = 5.0
    landmarks_per_packet: int = 40
    dock_settle_fits: int = 5
    dock_axes_tol: float = 0.02
    dock_slot_tol_m: float = 0.3
    noise_bound_m: float = 0.1
    mean_motion_radps: float = 0.0011    # 500 km circular LEO (overridden by the OrbitInfo)

    @property
    def inertia(self) -> np.ndarray:
        return np.eye(3) * self.inertia_kgm2

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> "CaptureParams":
        names = {f.name for f in fields(cls)}
        # the scenario loader passes [actuator].max_accel_mps2 to every controller; this agent limits
        # by force (force_max_n), the plant by each [[spacecraft]] max_force_n: ignored here
        unknown = set(params) - names - {"name", "max_accel_mps2"}
        if unknown:
            raise ValueError(f"unknown p000-capture parameters {sorted(unknown)}")
        p = replace(cls(), **{k: v for k, v in params.items() if k in names})
        if p.chase_law not in ("literal", "governed"):
            raise ValueError(f"chase_law must be 'literal' or 'governed', got {p.chase_law!r}")
        if p.broadcast not in ("event", "every-step", "periodic"):
            raise ValueError(f"broadcast must be event|every-step|periodic, got {p.broadcast!r}")
        if p.search_attitude not in ("scan", "hold"):
            raise ValueError(f"search_attitude must be 'scan' or 'hold', got {p.search_attitude!r}")
        return p
