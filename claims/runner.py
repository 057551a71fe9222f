"""Rerun claims: compute their sources (cached, one run shared by its claims), compare with the registry."""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from swarmhil.claims.model import Claim, Source, Table, Value
from swarmhil.claims.render import doc_line, row_values, verdicts

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
        self.cpu_s: dict[str, float] = {}  # CPU time of the process that ran the source, while it ran
        self.failed: dict[str, Exception] = {}

    def _file(self, name: str) -> Path | None:
        if self.dir is None:
            return None
        key = kernel_set().replace(" ", "_").replace("=", "-")
        return self.dir / key / f"{name}.json"

    def _load(self, name: str) -> bool:
        """Whether the result is at hand (in memory, or read now from the disk cache)."""
        if name in self.mem:
            return True
        f = self._file(name)
        if f is not None and f.is_file():
            self.mem[name] = json.loads(f.read_text())
            return True
        return False

    def _store(self, name: str, res: dict[str, Any], wall_s: float, cpu_s: float) -> None:
        self.wall_s[name], self.cpu_s[name] = wall_s, cpu_s
        self.log(f"source {name}: {wall_s:.1f} s wall, {cpu_s:.1f} s CPU")
        self.mem[name] = res
        f = self._file(name)
        if f is not None:
            f.parent.mkdir(parents=True, exist_ok=True)
            f.write_text(json.dumps(res, indent=1, default=str))

    def get(self, name: str) -> dict[str, Any]:
        """The source's result; a source that failed fails again at once, without a second run."""
        if name in self.failed:
            raise self.failed[name]
        if self._load(name):
            return self.mem[name]
        self.log(f"source {name}: {self.sources[name].what}")
        t0, c0 = time.monotonic(), time.process_time()
        try:
            res = self.sources[name].run(self.get)
        except Exception as exc:
            self.failed[name] = exc
            raise
        self._store(name, res, time.monotonic() - t0, time.process_time() - c0)
        return res

    def prefetch(self, names: Iterable[str], jobs: int) -> None:
        """Run the sources `names` need that make a run of their own (no `uses`), `jobs` at a time in
        worker processes (same environment, so the same kernel set); derived sources are then
        computed from them in this process by `get`. Each source still runs once."""
        need: list[str] = []
        todo = list(names)
        while todo:
            n = todo.pop(0)
            if n not in need:
                need.append(n)
                todo += list(self.sources[n].uses)
        leaves = [n for n in need if not self.sources[n].uses and not self._load(n)]
        if jobs <= 1 or len(leaves) < 2:
            return
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futs = {pool.submit(_run_source, n): n for n in leaves}
            for fut in as_completed(futs):
                try:
                    res, wall, cpu = fut.result()
                except Exception as exc:  # noqa: BLE001 - reported by each of its claims
                    self.failed[futs[fut]] = exc
                    self.log(f"source {futs[fut]}: {type(exc).__name__}: {exc}")
                    continue
                self._store(futs[fut], res, wall, cpu)


def _run_source(name: str) -> tuple[dict[str, Any], float, float]:
    """A worker process: one source that makes its own run (it reads no other source)."""
    from swarmhil.claims.registry import registry

    def no_get(other: str) -> dict[str, Any]:
        raise RuntimeError(f"source {name} reads {other}: declare it in `uses`")

    reg = registry()
    t0, c0 = time.monotonic(), time.process_time()
    res = reg.sources[name].run(no_get)
    return res, time.monotonic() - t0, time.process_time() - c0


def _run_nudged(name: str, k: int) -> dict[str, Any]:
    """A worker process: the k-th one-ulp nudged run of a source."""
    from swarmhil.claims.registry import registry

    nudged = registry().sources[name].nudged
    assert nudged is not None
    return nudged(k)(lambda other: {})


def nudged_values(claims: Iterable[Claim], sources: Mapping[str, Source], n: int, jobs: int,
                  log: Callable[[str], None] = lambda s: None) -> dict[str, list[float]]:
    """Each numeric claim's values over its source's nudged runs k = 1..n (sources without nudged
    runs are left out), the runs `jobs` at a time in worker processes."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    chosen = [c for c in claims if sources[c.source].nudged is not None]
    names = list(dict.fromkeys(c.source for c in chosen))
    runs: dict[tuple[str, int], dict[str, Any]] = {}
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        futs = {(name, k): pool.submit(_run_nudged, name, k) for name in names for k in range(1, n + 1)}
        for key, fut in futs.items():
            runs[key] = fut.result()
            log(f"source {key[0]}: nudge {key[1]} done")
    out: dict[str, list[float]] = {}
    for c in chosen:
        vals = [as_value(c.compute(runs[(c.source, k)])) for k in range(1, n + 1)]
        if all(isinstance(v, (int, float)) for v in vals):
            out[c.id] = [float(v) for v in vals]  # type: ignore[arg-type]
    return out


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

