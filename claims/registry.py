"""The one claims registry: every module's sources, claims and tables, with the recorded values.

Recorded values live in claims/recorded.json, `{claim id: {"value": ..., "alt": ..., "kernel_alt":
..., "nudged": [...], "machines": {...}}}`, written by `swarmhil claims --all --record` (value,
default kernels), by the same under the other kernel set (alt) and, for sources with one-ulp nudged
runs, by `--record --nudges N` (nudged); `machines` keeps, by processor, the default kernels' value
another processor gave where it left the tolerance (docs/claims.md). Tolerances are in the
modules, chosen from these spreads.
"""
from __future__ import annotations

import dataclasses
import json
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any

from swarmhil.claims.model import Claim, Source, Table, band_reaches_zero, resolve_tol

RECORDED = Path(__file__).resolve().parent / "recorded.json"


def modules() -> list[ModuleType]:
    """The registry's modules, one per doc or paper."""
    from swarmhil.claims import (camera_navigation, faults, mission_floors, p000_speed, paper000, paper000_repro,
                                 paper000_stack, paper001, paper001_study, paper002, paper003, paper004, performance,
                                 reliability, rtf)

    return [paper000, paper000_stack, paper000_repro, paper001, paper001_study, paper002, paper003, paper004, performance,
            reliability, rtf, mission_floors, p000_speed, camera_navigation, faults]


def _value(v: Any) -> Any:
    return tuple(v) if isinstance(v, list) else v


def read_recorded(path: Path = RECORDED) -> dict[str, dict[str, Any]]:
    """claims/recorded.json ({} when absent)."""
    return json.loads(path.read_text()) if path.is_file() else {}


@dataclasses.dataclass(frozen=True)
class Registry:
    sources: dict[str, Source]
    claims: dict[str, Claim]
    tables: dict[str, Table]

    def tier(self, claim: Claim) -> str:
        return self.sources[claim.source].tier

    def select(self, tiers: tuple[str, ...]) -> list[Claim]:
        return [c for c in self.claims.values() if self.tier(c) in tiers]


def refuse_band_reaching_zero(claim: Claim) -> None:
    """A claim whose tolerance band reaches zero for a non-zero value is refused: it would pass a
    measured 0 (docs/claims.md "The cap"). Declare it `residual=True` when it is a difference meant
    to be about zero, or narrow its tolerance."""
    if band_reaches_zero(claim):
        lo, hi = claim.tol.band(float(claim.value))  # type: ignore[arg-type]
        raise ValueError(f"claim {claim.id}: its band [{lo:.4g}, {hi:.4g}] reaches zero for the value "
                         f"{claim.value:.4g} ({claim.tol.describe()}); narrow it or declare the claim a residual")


@lru_cache(maxsize=1)
def registry() -> Registry:
    """All modules merged, recorded values attached; duplicate ids, dangling references and bands
    reaching zero refused."""
    rec = read_recorded()
    sources: dict[str, Source] = {}
    claims: dict[str, Claim] = {}
    tables: dict[str, Table] = {}
    for m in modules():
        for s in m.SOURCES:
            if s.name in sources:
                raise ValueError(f"source {s.name} twice")
            sources[s.name] = s
        for c in m.CLAIMS:
            if c.id in claims:
                raise ValueError(f"claim {c.id} twice")
            r = rec.get(c.id, {})
            value, alt = _value(r.get("value")), _value(r.get("alt"))
            nudged = tuple(float(v) for v in r.get("nudged", ()))
            machines = tuple(float(v) for v in r.get("machines", {}).values())
            claims[c.id] = dataclasses.replace(c, value=value, alt=alt, nudged=nudged, machines=machines,
                                               tol=resolve_tol(c.tol, value, alt, c.fmt, nudged=nudged,
                                                               machines=machines, residual=c.residual))
            refuse_band_reaching_zero(claims[c.id])
        for t in m.TABLES:
            if t.id in tables:
                raise ValueError(f"table {t.id} twice")
            tables[t.id] = t
    for c in claims.values():
        if c.source not in sources:
            raise ValueError(f"claim {c.id}: no source {c.source}")
    for t in tables.values():
        for k in t.placeholders():
            if k not in claims:
                raise ValueError(f"table {t.id}: no claim {k}")
    return Registry(sources, claims, tables)


def record(measured: dict[str, Any], field: str, kernel: str, path: Path = RECORDED) -> None:
    """Merge measured values into claims/recorded.json as `value` (default kernels), `alt`, or
    `nudged` (the list of the one-ulp nudged runs' values, default kernels)."""
    rec = read_recorded(path)
    for k, v in measured.items():
        e = rec.setdefault(k, {})
        e[field] = list(v) if isinstance(v, tuple) else v
        if field == "alt":
            e["kernel_alt"] = kernel
    path.write_text(json.dumps(dict(sorted(rec.items())), indent=1) + "\n")
