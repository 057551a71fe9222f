"""Link faults of the `[[fault]]` schedule (issue 27; plant/faults.py holds the schedule): pure
functions over index arrays, and the per-packet view the link model asks for (link/model.py).

- `link_partition`: spacecraft in different `groups` cannot hear each other (ids named in no group
  form one more group); a packet across groups is dropped, counted as `dropped_fault`.
- `link_degraded`: on the links between the two sets of `between` (both ways; every link when
  omitted), an extra loss probability (drawn counter-based, like the link's own loss, so it does not
  depend on the order packets are evaluated in; counted as `dropped_fault`) and an extra latency.

A fault acts on the packets *sent* at a step inside its window (`FaultWindow`: step indices, the
same in the plant and the channel).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from swarmhil.plant.faults import FaultWindow, LinkDegraded, LinkPartition


def group_of(groups: Sequence[Sequence[str]], ids: Sequence[str]) -> np.ndarray:
    """(N,) group index of every spacecraft; those in no group share the index len(groups)."""
    index = {s: i for i, s in enumerate(ids)}
    out = np.full(len(ids), len(groups), dtype=np.int64)
    for g, members in enumerate(groups):
        out[[index[s] for s in members]] = g
    return out


def partitioned(group: np.ndarray, src: int, dst: np.ndarray) -> np.ndarray:
    """(R,) True where receiver dst[r] is in another group than the sender src."""
    return group[dst] != group[src]


def between_mask(a: np.ndarray, b: np.ndarray, src: int, dst: np.ndarray) -> np.ndarray:
    """(R,) True where the link src -> dst[r] joins set a and set b (either way); a, b (N,) bool."""
    return (a[src] & b[dst]) | (b[src] & a[dst])


@dataclass(frozen=True)
class PacketFaults:
    """What the link faults do to one packet, per addressed receiver (R,)."""

    blocked: np.ndarray        # bool: dropped by a partition
    loss_probability: np.ndarray  # extra loss of degraded links (combined: 1 - prod(1 - p))
    extra_latency_s: np.ndarray


class LinkFaults:
    """The link faults of a scenario over the channel's spacecraft order."""

    def __init__(self, faults: list[Any], ids: Sequence[str], step_s: float) -> None:
        ids = list(ids)
        index = {s: i for i, s in enumerate(ids)}
        self.partitions: list[tuple[FaultWindow, np.ndarray]] = []
        self.degraded: list[tuple[FaultWindow, np.ndarray | None, np.ndarray | None, LinkDegraded]] = []
        for f in faults:
            w = FaultWindow.of(f, step_s)
            if isinstance(f, LinkPartition):
                self.partitions.append((w, group_of(f.groups, ids)))
            elif isinstance(f, LinkDegraded):
                a = b = None
                if f.between:
                    a, b = (np.isin(np.arange(len(ids)), [index[s] for s in side]) for side in f.between)
                self.degraded.append((w, a, b, f))

    def __bool__(self) -> bool:
        return bool(self.partitions or self.degraded)

    def at(self, step: int, src: int, dst: np.ndarray) -> PacketFaults | None:
        """The faults acting on a packet sent at `step` by src to receivers dst (None: no fault)."""
        parts = [g for w, g in self.partitions if w.active(step)]
        degr = [(a, b, f) for w, a, b, f in self.degraded if w.active(step)]
        if not parts and not degr:
            return None
        blocked = np.zeros(len(dst), dtype=bool)
        for g in parts:
            blocked |= partitioned(g, src, dst)
        keep = np.ones(len(dst))
        latency = np.zeros(len(dst))
        for a, b, f in degr:
            on = np.ones(len(dst), dtype=bool) if a is None or b is None else between_mask(a, b, src, dst)
            keep *= np.where(on, 1.0 - f.loss_probability, 1.0)
            latency += np.where(on, f.extra_latency_s, 0.0)
        return PacketFaults(blocked, 1.0 - keep, latency)
