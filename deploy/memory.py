"""The launcher's memory check (issue 16): before starting N processes, what they need against what
the machine has available (docs/cli.md "Memory check before a multi-process run")."""
from __future__ import annotations

import os
from typing import Any

# Peak RSS per process, rounded up from bench/agent_rss.py (docs/performance.md "Agent memory and
# imports"): an ideal-sensing agent 54 MB, a camera + filter agent (numba) 225 MB, plant / recorder /
# companions 110-135 MB.
AGENT_MB = {"scene": 240.0}
AGENT_MB_DEFAULT = 60.0
GROUND_MB = 150.0


class NotEnoughMemory(RuntimeError):
    """The machine has less memory available than the run's processes need."""


def check_memory(sc: Any, n_ground: int) -> float:
    """Refuse (NotEnoughMemory, one line) before starting anything when N agents x their figure plus
    the ground processes need more than the memory available now (psutil); returns the need in MB.
    SWARMHIL_MEMORY_CHECK=off skips it."""
    per_agent = AGENT_MB.get(sc.sensing["kind"], AGENT_MB_DEFAULT)
    need = len(sc.ids) * per_agent + n_ground * GROUND_MB
    if os.environ.get("SWARMHIL_MEMORY_CHECK", "").lower() == "off":
        return need
    import psutil

    avail = psutil.virtual_memory().available / 1e6
    if need > avail:
        raise NotEnoughMemory(
            f"not enough memory: {len(sc.ids)} agent processes x {per_agent:.0f} MB + {n_ground} ground processes x "
            f"{GROUND_MB:.0f} MB need about {need:,.0f} MB, {avail:,.0f} MB are available; run fewer agents, "
            f"--in-process, or free memory (SWARMHIL_MEMORY_CHECK=off skips this check)")
    return need
