"""What the capture mission measures, as it arrives in `Observation.extra` (paper 000 §2.2, §3.2.2).

The names, shapes and frames are the room's contract (missions/p000_capture/contract.py), which the
plant's sensing kind `p000-landmarks` writes with; all are optional except the own state.
Neighbours' relative states come in the Observation's own neighbour rows (within R_h).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmhil.missions.p000_capture.contract import (LANDMARK_IDS, LANDMARKS_BODY_M, OMEGA_BODY_RADPS, POSITION_M,
                                            Q_BODY_TO_LVLH, SURFACE_REL_M, VELOCITY_MPS)


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
        lm = np.asarray(extra[LANDMARKS_BODY_M] if LANDMARKS_BODY_M in extra else np.zeros((0, 3)), dtype=float).reshape(-1, 3)
        ids = np.asarray(extra[LANDMARK_IDS] if LANDMARK_IDS in extra else -np.ones(len(lm)), dtype=int).reshape(-1)
        if len(ids) != len(lm):
            raise ValueError(f"{len(lm)} landmark returns but {len(ids)} ids")
        surf = extra.get(SURFACE_REL_M)
        return cls(_vec(extra, Q_BODY_TO_LVLH, 4), _vec(extra, OMEGA_BODY_RADPS, 3), _vec(extra, POSITION_M, 3),
                   _vec(extra, VELOCITY_MPS, 3), lm, ids,
                   None if surf is None else np.asarray(surf, dtype=float).reshape(3))

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            Q_BODY_TO_LVLH: self.q_body_to_lvlh, OMEGA_BODY_RADPS: self.omega_body_radps,
            POSITION_M: self.position_m, VELOCITY_MPS: self.velocity_mps,
            LANDMARKS_BODY_M: self.landmarks_body_m, LANDMARK_IDS: self.landmark_ids,
        }
        if self.surface_rel_m is not None:
            d[SURFACE_REL_M] = self.surface_rel_m
        return d


def _vec(extra: dict[str, Any], key: str, n: int) -> np.ndarray:
    """extra[key] as a float vector of n entries (KeyError if absent, ValueError if another shape)."""
    if key not in extra:
        raise KeyError(f"obs.extra lacks {key!r} (keys: {sorted(extra)})")
    v = np.asarray(extra[key], dtype=float).reshape(-1)
    if v.shape != (n,):
        raise ValueError(f"{key} has shape {v.shape}, expected ({n},)")
    return v
