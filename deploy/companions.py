"""Optional companion processes of a run (link channel, viewer bridge): one registry, two modes.

A companion is started by the launcher as its own process (`python -m swarmhil.deploy.proc companion
--name NAME`) or, in in-process runs, on the in-memory bus. Companions that take part in
lockstep (the link channel) publish a barrier `Tick` on `swarm/<run>/sync/<name>` with
header.step = k once everything of step k is done; the plant waits for it like a command.

Each entry names a module that defines:
    enabled(sc: Scenario, opts: dict) -> bool
    start(bus, run: str, sc: Scenario, out: Path, opts: dict) -> object with .close() -> dict
    LOCKSTEP_BARRIER: bool
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any

COMPANIONS: dict[str, str] = {
    "channel": "swarmhil.link.node",
    "viz": "swarmhil.dashboards.viz_node",
}


@dataclass
class Companion:
    name: str
    module: ModuleType

    @property
    def barrier(self) -> bool:
        return bool(getattr(self.module, "LOCKSTEP_BARRIER", False))


def load(name: str) -> Companion:
    if name not in COMPANIONS:
        raise ValueError(f"unknown companion {name!r}; known: {sorted(COMPANIONS)}")
    return Companion(name, importlib.import_module(COMPANIONS[name]))


def enabled_companions(sc: Any, opts: dict[str, Any]) -> list[Companion]:
    out = []
    for name, modname in COMPANIONS.items():
        try:
            mod = importlib.import_module(modname)
        except ModuleNotFoundError as exc:
            if exc.name == modname:
                continue  # not built yet
            raise
        if mod.enabled(sc, opts):
            out.append(Companion(name, mod))
    return out
