"""Rerun claims: compute their sources (cached, one run shared by its claims), compare with the registry."""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from claims.model import Claim, Source, Table, Value
from claims.render import doc_line, row_values, verdicts

KERNEL_ENV = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")


def kernel_set() -> str:
    """Which kernel set this process uses: 'default', or the environment that changed it."""
    parts = [f"{k}={os.environ[k]}" for k in KERNEL_ENV if os.environ.get(k)]
    return " ".join(parts) or "default"


def as_value(v: Any) -> Value:
    """A claim's computed value in the registry's types (lists of names become tuples)."""
    if isinstance(v, list):
        return tuple(str(x) for x in v)
    if isinstance(v, bool):
        return int(v)
    return v


@dataclass
class Outcome:
    """One claim rerun: the value measured now against the recorded one."""

    claim: Claim
    measured: Value | None
    ok: bool
    error: str = ""
    where: str = ""


class SourceCache:
    """Source results per kernel set: in memory, and on disk under `cache_dir` when given
    (`swarmhil claims --cache DIR`; never used by the tests, so a stale file cannot hide drift)."""

    def __init__(self, sources: Mapping[str, Source], cache_dir: Path | None = None,
                 log: Callable[[str], None] = lambda s: None) -> None:
        self.sources, self.dir, self.log = sources, cache_dir, log
        self.mem: dict[str, dict[str, Any]] = {}
        self.wall_s: dict[str, float] = {}

    def _file(self, name: str) -> Path | None:
        if self.dir is None:
            return None
        key = kernel_set().replace(" ", "_").replace("=", "-")
        return self.dir / key / f"{name}.json"

    def get(self, name: str) -> dict[str, Any]:
        if name in self.mem:
            return self.mem[name]
        f = self._file(name)
        if f is not None and f.is_file():
            self.mem[name] = json.loads(f.read_text())
            return self.mem[name]
        self.log(f"source {name}: {self.sources[name].what}")
        t0 = time.monotonic()
        res = self.sources[name].run(self.get)
        self.wall_s[name] = time.monotonic() - t0
        self.log(f"source {name}: {self.wall_s[name]:.1f} s")
        self.mem[name] = res
        if f is not None:
            f.parent.mkdir(parents=True, exist_ok=True)
            f.write_text(json.dumps(res, indent=1, default=str))
        return res


def rerun(claims: Iterable[Claim], cache: SourceCache) -> list[Outcome]:
    """Each claim computed from its (cached) source and checked against its recorded value."""
    out = []
    for c in claims:
        try:
            v = as_value(c.compute(cache.get(c.source)))
        except Exception as exc:  # noqa: BLE001 - one claim's failure is reported, the others go on
            out.append(Outcome(c, None, False, f"{type(exc).__name__}: {exc}"))
            continue
        out.append(Outcome(c, v, c.tol.holds(v, c.value)))
    return out


def verdict_changes(tables: Mapping[str, Table], claims: Mapping[str, Claim],
                    measured: Mapping[str, Value]) -> list[str]:
    """Rows whose verdict, computed from the values measured now, differs from the doc's (recorded)
    one: a "reproduced" stands only where its claims still give it. Rows with an unmeasured claim
    are skipped."""
    out = []
    for tid, t in tables.items():
        now = verdicts(t, claims, measured)
        then = verdicts(t, claims)
        for i, (row_ids, a, b) in enumerate(zip(row_values(t, claims), then, now)):
            if a != b and all(k in measured for k in row_ids):
                out.append(f"{t.doc}:{doc_line(t, i)} ({tid} row {i + 1}): verdict {a!r} recorded, {b!r} now")
    return out


def locate(claims: Mapping[str, Claim], tables: Mapping[str, Table]) -> dict[str, str]:
    """claim id -> 'doc:line' of the first table row that shows it."""
    out: dict[str, str] = {}
    for t in tables.values():
        for i, ids in enumerate(row_values(t, claims)):
            for k in ids:
                out.setdefault(k, f"{t.doc}:{doc_line(t, i)}")
    return out

