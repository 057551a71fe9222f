"""Report sections: one registered module per mission (issue 11). `swarmhil report RUN` runs every
section whose `applies(config)` is true for the run's recorded configuration, puts its metrics in
`summary.json["metrics"][name]` and its figures on the run's report page under its own heading.

    @register_section("p001-formation", applies=lambda cfg: uses_controller(cfg, "p001-lattice"))
    def formation(ctx: SectionContext) -> SectionResult: ...

A section reads only the recording (ctx.truth from dashboards/truth_io.py, ctx.config the resolved
configuration, ctx.mcap for anything else) and writes its PNGs into ctx.out. Every module of this
package (the sections every run may have, and paper 002's) and every mission room's report,
missions/<room>/report (bus/discovery.py `import_role`), is imported on first use, so adding a
section is adding a module.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from swarmhil.bus.discovery import RoomError, add_rooms, import_all, import_role


@dataclass
class SectionContext:
    run_dir: Path
    mcap: Path
    out: Path                    # where the figures go (RUN/report)
    summary: dict[str, Any]
    config: dict[str, Any]       # the resolved configuration the recording carries ({} for old recordings)
    truth: Any                   # dashboards.truth_io.TruthArrays
    swarm: Any = None            # dashboards.metrics.SwarmMetrics of the run (its per-step series)
    interactive: bool = True     # many-line figures may also be Plotly (dashboards/site.py line_figure)
    projection_orbits: float | None = 3.0  # the trailing window of projection figures (None: whole run)


@dataclass
class SectionResult:
    title: str
    metrics: dict[str, Any] = field(default_factory=dict)
    figures: list[Any] = field(default_factory=list)  # (file name in ctx.out, caption), or a site figure
    html: str = ""                                                # extra HTML (tables), already escaped


Section = Callable[[SectionContext], SectionResult]
_SECTIONS: dict[str, tuple[Callable[[dict[str, Any]], bool], Section]] = {}


def register_section(name: str, applies: Callable[[dict[str, Any]], bool]) -> Callable[[Section], Section]:
    def deco(fn: Section) -> Section:
        _SECTIONS[name] = (applies, fn)
        return fn

    return deco


def controllers_of(config: dict[str, Any]) -> set[str]:
    """Every controller a run's spacecraft flew (the swarm's and the per-spacecraft ones)."""
    names = {str((config.get("controller") or {}).get("name"))}
    for s in config.get("spacecraft") or []:
        if s.get("controller"):
            names.add(str(s["controller"]))
    return names


@dataclass(frozen=True)
class ErrorSeries:
    """A mission's own error metric over a run (what its section calls the error: paper 004's
    tracking error, ...), per recorded step, for the faults section's excursions."""

    name: str                    # what it is, for the report ("largest servicer tracking error")
    unit: str
    t_s: Any                     # (T,) seconds
    values: Any                  # (T,)


ErrorMetric = Callable[[SectionContext], ErrorSeries]
_ERROR_METRICS: dict[str, tuple[Callable[[dict[str, Any]], bool], ErrorMetric]] = {}


def register_error_metric(name: str, applies: Callable[[dict[str, Any]], bool]) -> Callable[[ErrorMetric], ErrorMetric]:
    """A mission's section declares its error metric (issue 27: recovery per mission)."""
    def deco(fn: ErrorMetric) -> ErrorMetric:
        _ERROR_METRICS[name] = (applies, fn)
        return fn

    return deco


def error_metrics_for(config: dict[str, Any]) -> list[tuple[str, ErrorMetric]]:
    _load()
    return [(name, fn) for name, (applies, fn) in sorted(_ERROR_METRICS.items()) if applies(config)]


def uses_controller(config: dict[str, Any], *names: str) -> bool:
    return bool(controllers_of(config) & set(names))


def _load() -> None:
    import_all(__name__)
    import_role("report")


_MISSING_ROOMS: set[str] = set()
"""Rooms a recording names that do not import here (said once)."""


def sections_for(config: dict[str, Any]) -> list[tuple[str, Section]]:
    """The sections that apply to a run, by its recorded configuration: the tree's and those of the
    rooms the run named from outside the tree ([run].rooms), when they import here; a room that
    does not is said on stderr and its section left out (the rest of the report is written)."""
    for room in (config.get("run") or {}).get("rooms") or []:
        try:
            add_rooms([room])
        except RoomError as exc:
            if room not in _MISSING_ROOMS:  # said once per process
                _MISSING_ROOMS.add(room)
                print(f"swarmhil report: {exc}: its report section is left out", file=sys.stderr)
    _load()
    return [(name, fn) for name, (applies, fn) in sorted(_SECTIONS.items()) if applies(config)]
