"""Check a source's claims from a run a test already made (the run the source would make), so a
run made by a test in CI is not made a second time by `swarmhil claims --all` (docs/claims.md
"Runs made once"). The test calls `claim_failures(source, run)` and asserts it is empty."""
from __future__ import annotations

from typing import Any


def claim_failures(source: str, run: Any) -> list[str]:
    """One line per claim of `source` that the run does not give within its tolerance."""
    from swarmhil.claims.registry import registry
    from swarmhil.claims.runner import SourceCache, rerun

    reg = registry()
    src = reg.sources[source]
    if src.from_run is None:
        raise ValueError(f"source {source}: no from_run, cannot be checked from a test's run")
    cache = SourceCache(reg.sources)
    cache.mem[source] = src.from_run(run)
    outs = rerun([c for c in reg.claims.values() if c.source == source], cache)
    if not outs:
        raise ValueError(f"source {source}: no claims")
    return [f"{o.claim.id}: {o.error or o.measured!r} (recorded {o.claim.value!r}, {o.claim.tol.describe()})"
            for o in outs if not o.ok]
