"""What the far and near layers need beyond the neighbours: the agent's own CW state.

Stands for absolute navigation (a GNSS-like receiver at GEO, or ground orbit determination
uplinked) differenced with the reference point's ephemeris, expressed in the reference point's
CW frame (x radial outward, y along-track, z orbit normal). The plant puts it in `Observation.extra`
under the keys below; neighbours' relative states (within r_Z) come in the Observation's own fields.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

OWN_POSITION_KEY = "own_position_m"
OWN_VELOCITY_KEY = "own_velocity_mps"


@dataclass(frozen=True)
class OwnState:
    """The agent's position (m) and velocity (m/s) relative to the reference point, CW frame."""

    position_m: np.ndarray
    velocity_mps: np.ndarray

    @classmethod
    def from_extra(cls, extra: dict[str, Any]) -> "OwnState":
        missing = [k for k in (OWN_POSITION_KEY, OWN_VELOCITY_KEY) if k not in extra]
        if missing:
            raise KeyError(f"observation.extra lacks {missing}; has {sorted(extra)}")
        r = np.asarray(extra[OWN_POSITION_KEY], dtype=float).reshape(3)
        v = np.asarray(extra[OWN_VELOCITY_KEY], dtype=float).reshape(3)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
            raise ValueError(f"non-finite own state r={r} v={v}")
        return cls(position_m=r, velocity_mps=v)

    def to_extra(self) -> dict[str, list[float]]:
        return {OWN_POSITION_KEY: [float(x) for x in self.position_m],
                OWN_VELOCITY_KEY: [float(x) for x in self.velocity_mps]}
