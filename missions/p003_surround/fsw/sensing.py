"""What each craft measures, as typed `obs.extra` entries (relative sensing only, §2).

The keys are the contract's (missions/p003_surround/contract.py `TARGET_REL_KEY`, `LEADER_REL_KEY`):

- leader: `obs.extra["p003.target_rel"]` = the target's position and velocity relative to the
  leader, q_TL = r_T - r_L and q'_TL, in the leader's LVLH (Assumption 1);
- servicer i: `obs.extra["p003.leader_rel"]` = its own position and velocity relative to the
  leader, q_Li = r_i - r_L and q'_Li, in the leader's LVLH.
On the stack (missions/p003_surround/sense.py, sensing kind `p003-relative`) each arrives as two named
arrays, `obs.extra["<key>.position_m/<subject>"]` and `obs.extra["<key>.velocity_mps/<subject>"]`
(subject: the target's or the leader's id, whichever it is); an in-process loop may instead hand
one dict {"position_m": [3 floats], "velocity_mps": [3 floats]} (or the dataclass) under `<key>`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class RelativeState:
    """A relative position (m) and velocity (m/s) in the leader's LVLH."""

    position_m: np.ndarray
    velocity_mps: np.ndarray

    def __post_init__(self) -> None:
        for name in ("position_m", "velocity_mps"):
            arr = np.asarray(getattr(self, name), dtype=float)
            # all(isfinite) over the three Python floats: np.isfinite(arr).all() without numpy's calls (issue 29)
            if arr.shape != (3,) or not all(map(math.isfinite, arr.tolist())):
                raise ValueError(f"{name} must be 3 finite floats, got {getattr(self, name)!r}")
            object.__setattr__(self, name, arr)

    def to_dict(self) -> dict[str, list[float]]:
        return {"position_m": self.position_m.tolist(), "velocity_mps": self.velocity_mps.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "RelativeState":
        return cls(np.asarray(d["position_m"], dtype=float), np.asarray(d["velocity_mps"], dtype=float))


def _named(extra: dict[str, Any], name: str) -> Any:
    """The array named `name` or `name/<subject>` (exactly one), else None."""
    if name in extra:
        return extra[name]
    hits = [k for k in extra if k.startswith(name + "/")]
    if len(hits) > 1:
        raise KeyError(f"obs.extra has several {name!r} measurements: {sorted(hits)}")
    return extra[hits[0]] if hits else None


def read(extra: dict[str, Any], key: str) -> RelativeState:
    """The relative state under `key` in obs.extra (one dict or dataclass, or the two named arrays
    `key.position_m[/subject]`, `key.velocity_mps[/subject]`); KeyError naming the key if missing."""
    if key in extra:
        value = extra[key]
        return value if isinstance(value, RelativeState) else RelativeState.from_dict(value)
    pos, vel = _named(extra, f"{key}.position_m"), _named(extra, f"{key}.velocity_mps")
    if pos is None or vel is None:
        raise KeyError(f"obs.extra has no {key!r} (keys: {sorted(extra)})")
    return RelativeState(np.asarray(pos, dtype=float), np.asarray(vel, dtype=float))


def read_rows(extras: list[dict[str, Any]], key: str) -> tuple[np.ndarray, np.ndarray]:
    """(S, 3) positions and velocities of `read(e, key)` for every e of `extras`, stacked (the same
    float64 values), checked once over the stack (issue 29); what `read` raises otherwise, for the
    first e it raises for."""
    pos, vel = [], []
    pos_name, vel_name = f"{key}.position_m", f"{key}.velocity_mps"
    seen: tuple[str, str] | None = None  # the two names `_named` found in the last e
    for e in extras:
        if seen is not None and len(e) == 2 and seen[0] in e and seen[1] in e:  # those two alone: what `_named` finds
            p, v = e[seen[0]], e[seen[1]]
        elif key in e:
            s = read(e, key)
            p, v = s.position_m, s.velocity_mps
        else:
            p, v = _named(e, pos_name), _named(e, vel_name)
            if p is None or v is None:
                read(e, key)  # its KeyError
            names = [k for k in e if k == pos_name or k.startswith(pos_name + "/")]
            names += [k for k in e if k == vel_name or k.startswith(vel_name + "/")]
            seen = (names[0], names[1]) if len(names) == 2 else None
        pos.append(p)
        vel.append(v)
    try:
        rp, rv = np.array(pos, dtype=float), np.array(vel, dtype=float)
        ok = rp.shape == rv.shape == (len(extras), 3) and math.isfinite(np.add.reduce(rp, axis=None) + np.add.reduce(rv, axis=None))
    except (TypeError, ValueError):  # ragged or not numbers: `read` says which
        ok = False
    if ok:  # (a finite sum: every entry finite)
        return rp, rv
    states = [read(e, key) for e in extras]
    return (np.array([s.position_m for s in states], dtype=float).reshape(-1, 3),
            np.array([s.velocity_mps for s in states], dtype=float).reshape(-1, 3))
