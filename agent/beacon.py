"""Agent beacon over the inter-satellite link (issue 5): id, mode, health, optional estimate summary.

Off unless the scenario has `[beacon] period_s = ...` (off in the paper-faithful scenarios).
"""
from __future__ import annotations

from typing import Any

from swarmhil.agent.controller import Command, Transmission
from swarmhil.bus import swarmhil_pb2 as pb


class BeaconEmitter:
    def __init__(self, sc_id: str, period_s: float, include_estimates: bool = False) -> None:
        if period_s <= 0:
            raise ValueError(f"beacon period_s must be > 0 (got {period_s})")
        self.id = sc_id
        self.period_s = period_s
        self.include_estimates = include_estimates
        self._next_t = 0.0

    def emit(self, step: int, t: float, cmd: Command) -> list[Transmission]:
        if t + 1e-9 < self._next_t:
            return []
        self._next_t = t + self.period_s
        b = pb.Beacon(id=self.id, mode=cmd.mode, health="ok")
        if self.include_estimates:
            for d in cmd.decisions:
                b.estimate_summary.extend(float(x) for x in d.roe_rel_m)
        return [Transmission(type="beacon", payload=b.SerializeToString())]


def beacon_from_config(cfg: dict[str, Any] | None, sc_id: str) -> BeaconEmitter | None:
    """The emitter of a `[beacon]` table (None when it is absent, disabled or has no period)."""
    if not cfg or not cfg.get("enabled", True) or "period_s" not in cfg:
        return None
    return BeaconEmitter(sc_id, float(cfg["period_s"]), bool(cfg.get("include_estimates", False)))
