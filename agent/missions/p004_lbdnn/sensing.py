"""What paper 004's servicer reads in `Observation.extra`, and the frame it is given in.

Relative positions to graph neighbours d_ij = q_j - q_i (eq. 9) arrive in
`obs.rel_position_m` (rows in the order of `obs.neighbour_ids`); for this room they are in
**inertial axes** (ECI), the frame of the Cartesian reading of paper 004 (NOTES-004), and so is
the commanded acceleration. The partial measurement of the defunct craft y_i = C_i (q0 - q_i)
(eq. 10), for servicers with b_i = 1, arrives in `obs.extra` under the keys below.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

KEY_Y = "p004.y_m"
"""y_i = C_i (q0 - q_i) + noise, (m_i,) metres, inertial axes; absent when not measured."""
KEY_Y_VALID = "p004.y_valid"
"""bool: y_i is a fresh measurement at this step (False or absent: no line of sight)."""


@dataclass(frozen=True)
class DefunctMeasurement:
    """The partial measurement of paper 004 eq. 10 for one step."""

    y_m: np.ndarray  # (m_i,)
    valid: bool = True

    @classmethod
    def from_extra(cls, extra: dict[str, Any], m_rows: int) -> DefunctMeasurement | None:
        """Read it from `obs.extra`; None when the step carries no valid y_i."""
        if KEY_Y not in extra or not bool(extra.get(KEY_Y_VALID, True)):
            return None
        y = np.atleast_1d(np.asarray(extra[KEY_Y], dtype=float))
        if y.shape != (m_rows,):
            raise ValueError(f"{KEY_Y} has shape {y.shape}, expected ({m_rows},) rows of C_i")
        if not np.all(np.isfinite(y)):
            raise ValueError(f"{KEY_Y} is not finite: {y}")
        return cls(y_m=y, valid=True)

    def to_extra(self) -> dict[str, Any]:
        """The `obs.extra` entries a plant / sensing model writes for this measurement."""
        return {KEY_Y: np.asarray(self.y_m, dtype=float).tolist(), KEY_Y_VALID: bool(self.valid)}
