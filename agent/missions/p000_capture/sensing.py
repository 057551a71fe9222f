"""What the capture mission measures, as it arrives in `Observation.extra` (paper 000 §2.2, §3.2.2).

Keys (all optional except the own state; arrays as lists or numpy):
  p000_q_body_to_lvlh   (4,)   own attitude quaternion, scalar first, body -> LVLH
  p000_omega_body_radps (3,)   own body rate in the body frame
  p000_position_m       (3,)   own position in the CW frame centred on the target's initial position
  p000_velocity_mps     (3,)   own velocity in that frame
  p000_landmarks_body_m (K, 3) landmark returns in the body (sensor) frame; may hold outliers
  p000_landmark_ids     (K,)   landmark ids, −1 for returns that are not a landmark (outliers)
  p000_surface_rel_m    (3,)   vector from the agent to the closest point of the true target
                               surface, LVLH, present only within R_h (proximity sensing)
Neighbours' relative states come in the Observation's own neighbour rows (within R_h).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

PREFIX = "p000_"


@dataclass
class CaptureSensing:
    q_body_to_lvlh: np.ndarray
    omega_body_radps: np.ndarray
    position_m: np.ndarray
    velocity_mps: np.ndarray
    landmarks_body_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    landmark_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    surface_rel_m: np.ndarray | None = None

    @classmethod
    def from_dict(cls, extra: dict[str, Any]) -> "CaptureSensing":
        def vec(key: str, n: int) -> np.ndarray:
            if PREFIX + key not in extra:
                raise KeyError(f"obs.extra lacks {PREFIX + key!r} (keys: {sorted(extra)})")
            v = np.asarray(extra[PREFIX + key], dtype=float).reshape(-1)
            if v.shape != (n,):
                raise ValueError(f"{PREFIX + key} has shape {v.shape}, expected ({n},)")
            return v

        lm = np.asarray(extra.get(PREFIX + "landmarks_body_m", np.zeros((0, 3))), dtype=float).reshape(-1, 3)
        ids = np.asarray(extra.get(PREFIX + "landmark_ids", -np.ones(len(lm))), dtype=int).reshape(-1)
        if len(ids) != len(lm):
            raise ValueError(f"{len(lm)} landmark returns but {len(ids)} ids")
        surf = extra.get(PREFIX + "surface_rel_m")
        return cls(vec("q_body_to_lvlh", 4), vec("omega_body_radps", 3), vec("position_m", 3),
                   vec("velocity_mps", 3), lm, ids,
                   None if surf is None else np.asarray(surf, dtype=float).reshape(3))

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            PREFIX + "q_body_to_lvlh": self.q_body_to_lvlh, PREFIX + "omega_body_radps": self.omega_body_radps,
            PREFIX + "position_m": self.position_m, PREFIX + "velocity_mps": self.velocity_mps,
            PREFIX + "landmarks_body_m": self.landmarks_body_m, PREFIX + "landmark_ids": self.landmark_ids,
        }
        if self.surface_rel_m is not None:
            d[PREFIX + "surface_rel_m"] = self.surface_rel_m
        return d
