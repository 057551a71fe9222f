"""What paper 004's servicer reads in `Observation.extra`, and the frame it is given in.

Relative positions to graph neighbours d_ij = q_j - q_i (eq. 9) arrive either in
`obs.rel_position_m` (rows in the order of `obs.neighbour_ids`; the in-process test loop) or, on
the stack, as named arrays `obs.extra["p004.d_m/<j>"]` (the plant's sensing kind `p004-partial`,
missions/p004_lbdnn/sense.py; `neighbour_positions`); both in **inertial axes** (ECI), the frame of the
Cartesian reading of paper 004 (NOTES-004), and so is the commanded acceleration. The partial
measurement of the defunct craft y_i = C_i (q0 - q_i) (eq. 10), for servicers with b_i = 1,
arrives in `obs.extra` under `KEY_Y` (or `KEY_Y + "/<defunct id>"` from the sensing kind). The
names are the room's contract (missions/p004_lbdnn/contract.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmhil.missions.p004_lbdnn.contract import KEY_D, KEY_Y

KEY_Y_VALID = "p004.y_valid"
"""bool: y_i is a fresh measurement at this step (False or absent: no line of sight). Written by the
in-process test loops (`DefunctMeasurement.to_extra`), not by the plant's sensing kind."""


def neighbour_positions(extra: dict[str, Any]) -> dict[str, np.ndarray]:
    """{j: d_ij} from the named arrays `p004.d_m/<j>` of `obs.extra` (empty when there are none)."""
    out = {}
    for key, value in extra.items():
        if key.startswith(KEY_D + "/"):
            d = np.asarray(value, dtype=float).reshape(-1)
            if d.shape != (3,) or not all(map(math.isfinite, d.tolist())):  # np.isfinite(d).all() for 3 floats
                raise ValueError(f"{key} must be 3 finite numbers, got {value!r}")
            out[key[len(KEY_D) + 1:]] = d
    return out


def _y_key(extra: dict[str, Any]) -> str | None:
    """`p004.y_m`, or the one `p004.y_m/<subject>` of the sensing kind."""
    if KEY_Y in extra:
        return KEY_Y
    keys = [k for k in extra if k.startswith(KEY_Y + "/")]
    if len(keys) > 1:
        raise ValueError(f"more than one partial measurement of the defunct craft: {keys}")
    return keys[0] if keys else None


@dataclass(frozen=True)
class DefunctMeasurement:
    """The partial measurement of paper 004 eq. 10 for one step."""

    y_m: np.ndarray  # (m_i,)
    valid: bool = True

    @classmethod
    def from_extra(cls, extra: dict[str, Any], m_rows: int) -> DefunctMeasurement | None:
        """Read it from `obs.extra`; None when the step carries no valid y_i."""
        key = _y_key(extra)
        if key is None or not bool(extra.get(KEY_Y_VALID, True)):
            return None
        y = np.atleast_1d(np.asarray(extra[key], dtype=float))
        if y.shape != (m_rows,):
            raise ValueError(f"{key} has shape {y.shape}, expected ({m_rows},) rows of C_i")
        if not all(map(math.isfinite, y.tolist())):  # np.isfinite(y).all() without numpy's calls
            raise ValueError(f"{key} is not finite: {y}")
        return cls(y_m=y, valid=True)

    def to_extra(self) -> dict[str, Any]:
        """The `obs.extra` entries a plant / sensing model writes for this measurement."""
        return {KEY_Y: np.asarray(self.y_m, dtype=float).tolist(), KEY_Y_VALID: bool(self.valid)}
