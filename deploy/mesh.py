"""One run over several hosts: a mesh of Zenoh routers (`swarmhil run SCENARIO --hosts K`).

Each host has its own router process (deploy/router.py); router i connects to every router j < i,
so the K routers form a full mesh (Zenoh's router-to-router routing carries every key between
them). Each agent is a client of its own host's router only; the plant (and so the clock), the
recorder, the companions and the launcher are on host 0. External flight software joins host 0's
router. Every router applies the run's authentication and access control (bus/acl.py) to its own
clients; the routers identify each other by the Zenoh ids set here, fresh for each run.

Placement rule (`placement`): `[[spacecraft]] host = N` where given, else round-robin over the hosts
in the scenario's order of spacecraft (the i-th spacecraft on host i mod K).
"""
from __future__ import annotations

import secrets
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

GROUND_HOST = 0  # plant, clock, recorder, companions, launcher, external flight software


def router_name(host: int) -> str:
    """The process (and, for host > 0, the user) name of a host's router: `router`, `router-1`, ..."""
    return "router" if host == GROUND_HOST else f"router-{host}"


def new_router_zid() -> str:
    """A fresh 128-bit Zenoh id in Zenoh's form (lowercase hex, no leading zero)."""
    return f"{secrets.randbits(128) | (1 << 127):032x}"


def placement(ids: Sequence[str], hosts: int, pinned: Mapping[str, int | None],
              names: Sequence[str] | None = None) -> dict[str, int]:
    """Host of each spacecraft's agent: `pinned[id]` where not None, else round-robin (i mod hosts).

    ValueError (one line) for hosts < 1 or a pinned host outside 0 .. hosts-1; `names`: the hosts'
    names in order (`swarmhil compose --hosts h1,h2,...`), which the line then lists."""
    if hosts < 1:
        raise ValueError(f"--hosts {hosts}: needs at least one host")
    out: dict[str, int] = {}
    for i, sid in enumerate(ids):
        h = pinned.get(sid)
        if h is None:
            h = i % hosts
        elif not 0 <= h < hosts:
            if names is not None:
                raise ValueError(f"[[spacecraft]] {sid}: host = {h}, but --hosts names {hosts} host"
                                 f"{'s' if hosts != 1 else ''}, numbered in the order given: "
                                 + ", ".join(f"{j} = {n}" for j, n in enumerate(names)))
            raise ValueError(f"[[spacecraft]] {sid}: host = {h}, but the run has {hosts} host"
                             f"{'s' if hosts != 1 else ''} (0 .. {hosts - 1}; give --hosts {h + 1} or more)")
        out[sid] = int(h)
    return out


def scenario_placement(sc: Any, hosts: int, names: Sequence[str] | None = None) -> dict[str, int]:
    """`placement` for a loaded scenario (its `[[spacecraft]] host` fields)."""
    return placement(list(sc.ids), hosts, {s.id: getattr(s, "host", None) for s in sc.spacecraft}, names)


def router_users(hosts: int, first: int = 1) -> list[str]:
    """The users the routers of hosts `first` .. K-1 authenticate as when they connect to others:
    `router-<i>` (a launcher's mesh: from host 1, host 0's router dials nobody; a compose project
    per host: from host 0, every router dials every other)."""
    return [f"router-{h}" for h in range(first, hosts)]


def process_hosts(agent_hosts: Mapping[str, int], ground: Iterable[str]) -> dict[str, int]:
    """process name -> host: the ground processes on host 0, `agent-<id>` on its placement."""
    out = {n: GROUND_HOST for n in ground}
    out.update({f"agent-{sid}": h for sid, h in agent_hosts.items()})
    return out
