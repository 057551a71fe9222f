"""Random fault schedules for campaigns (issue 27): `swarmhil campaign SCENARIO --faults FILE`.

FILE (TOML) says which faults a run may get and from which distributions; every run draws its own
schedule from its seed, and the drawn faults are added to the scenario's `[[fault]]` tables
(plant/faults.py validates them as if written by hand):

    [recovery]
    hold_s = 5400.0              # recovered: the swarm whole again after the fault and staying so this long
                                 # (default: the scenario's [recovery].hold_s, one orbit period unless it says)

    [[draw]]
    kind = "thruster_stuck_off"  # any [[fault]] kind (docs/faults.md)
    probability = 0.5            # the chance that a run gets this fault (default 1)
    targets = 1                  # how many spacecraft it strikes, drawn without replacement ...
    pool = ["sc01", "sc02"]      # ... from these (default: every spacecraft of the scenario)
    start_s = [600.0, 3600.0]    # uniform on [low, high] (or one number)
    duration_s = [300.0, 1800.0] # uniform (or one number); every drawn fault ends
    [draw.params]                # the kind's own fields: a number, or [low, high] drawn uniformly
    factor = [0.0, 0.5]

    [[draw]]
    kind = "link_partition"
    groups = 2                   # the pool shuffled into this many groups (sizes as even as can be)
    start_s = [1800.0, 3600.0]
    duration_s = 1800.0

The draw of seed s uses its own random stream, `SeedSequence([FAULT_STREAM, s])`: the scenario's
own draws (dispersion, noise) with seed s are the same with and without faults, so a fault run
and its baseline start from the same swarm. Pure functions; the campaign (deploy/campaign.py)
calls `draw_faults` in the worker that flies the run.
"""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from swarmhil.deploy.scenario import Scenario, parse_scenario
from swarmhil.plant.bodies import format_validation_error
from swarmhil.plant.faults import KINDS, MODELS

FAULT_STREAM = 0x27FA  # the first word of a campaign fault draw's seed sequence (issue 27)
Range = float | Annotated[list[float], Field(min_length=2, max_length=2)]
TARGETED = {k for k, m in MODELS.items() if "targets" in m.model_fields}


class FaultDrawError(ValueError):
    """A bad faults file; the message is one line naming the file, the table and the field."""


class Draw(BaseModel):
    """One `[[draw]]`: a fault kind a run may get, and the distributions of its fields."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    kind: str
    probability: float = Field(1.0, ge=0, le=1)
    targets: int = Field(1, ge=1)           # targeted kinds: how many spacecraft
    groups: int = Field(2, ge=2)            # link_partition: how many groups
    pool: list[str] | None = None           # the spacecraft drawn from (default: all)
    start_s: Range
    duration_s: Range
    params: dict[str, Range | list[float] | str | bool] = Field(default_factory=dict)

    @field_validator("kind")
    @classmethod
    def _kind(cls, v: str) -> str:
        if v not in KINDS:
            raise ValueError(f"is not a known fault kind; known: {list(KINDS)}")
        return v

    @field_validator("start_s", "duration_s")
    @classmethod
    def _range(cls, v: Range) -> Range:
        lo, hi = (v, v) if isinstance(v, float) else v
        if lo < 0 or hi < lo:
            raise ValueError(f"must be a number >= 0 or [low, high] with 0 <= low <= high (got {v!r})")
        return v

    @model_validator(mode="after")
    def _params(self) -> "Draw":
        own = set(MODELS[self.kind].model_fields) - {"kind", "name", "start_s", "end_s", "duration_s", "targets",
                                                     "groups"}
        bad = sorted(set(self.params) - own)
        if bad:
            raise ValueError(f"params.{bad[0]} is not a field of {self.kind}; its fields: {sorted(own)}")
        return self


class Recovery(BaseModel):
    """[recovery]: hold_s, how long the swarm must stay whole after a fault for it to count as
    recovered (None: the scenario's own [recovery].hold_s, by default one orbit period)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    hold_s: float | None = Field(None, ge=0)


class FaultDraws(BaseModel):
    """A faults file: the draws and the recovery criterion."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    draw: Annotated[list[Draw], Field(min_length=1)]
    recovery: Recovery = Field(default_factory=Recovery)


def read_fault_draws(path: str | Path) -> FaultDraws:
    """Read and validate a faults file (one-line errors); `load_fault_draws` also checks its ids."""
    src = str(path)
    try:
        doc = tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise FaultDrawError(f"{src}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise FaultDrawError(f"{src}: not TOML: {exc}") from None
    try:
        draws = FaultDraws.model_validate(doc)
    except ValidationError as exc:
        raise FaultDrawError(_one_line(src, exc)) from None
    return draws


def load_fault_draws(path: str | Path, ids: list[str]) -> FaultDraws:
    """Read and validate a faults file against the scenario's spacecraft ids (one-line errors)."""
    src = str(path)
    draws = read_fault_draws(path)
    known = set(ids)
    for i, d in enumerate(draws.draw):
        pool = d.pool if d.pool is not None else ids
        unknown = [s for s in pool if s not in known]
        if unknown:
            raise FaultDrawError(f"{src}: [[draw]][{i}].pool names unknown spacecraft id {unknown[0]!r}")
        need = d.targets if d.kind in TARGETED else (d.groups if d.kind == "link_partition" else 0)
        if len(pool) < need:
            raise FaultDrawError(f"{src}: [[draw]][{i}] needs {need} spacecraft from a pool of {len(pool)}")
    return draws


def _one_line(src: str, exc: ValidationError) -> str:
    e = exc.errors()[0]
    loc = e["loc"]
    if len(loc) >= 2 and loc[0] == "draw" and isinstance(loc[1], int):
        return format_validation_error(src, f"[[draw]][{loc[1]}]", _Shift(exc, 2), Draw)
    return format_validation_error(src, "", exc, FaultDraws)


class _Shift:
    """A ValidationError seen from `loc[n:]` (the table's own fields)."""

    def __init__(self, exc: ValidationError, n: int) -> None:
        self.exc, self.n = exc, n

    def errors(self) -> list[dict[str, Any]]:
        return [{**e, "loc": e["loc"][self.n:]} for e in self.exc.errors()[:1]]


def _uniform(rng: np.random.Generator, v: Any) -> Any:
    """A number stays; [low, high] of numbers is drawn uniformly; anything else (a vector, a name) stays."""
    if isinstance(v, list) and len(v) == 2 and all(isinstance(x, float | int) for x in v):
        return float(rng.uniform(v[0], v[1])) if v[0] != v[1] else float(v[0])
    return v


def draw_faults(draws: FaultDraws, ids: list[str], seed: int) -> list[dict[str, Any]]:
    """The `[[fault]]` tables of the run with this seed: for each draw, with its probability, one
    fault with start, duration, targets (or groups) and parameters drawn from its stream. Named
    `drawN-<kind>` (N: the draw's index) so a row says which draw it came from."""
    rng = np.random.default_rng(np.random.SeedSequence([FAULT_STREAM, int(seed)]))
    out: list[dict[str, Any]] = []
    for i, d in enumerate(draws.draw):
        hit = rng.random() < d.probability  # drawn for every draw, so later draws do not shift with it
        start, duration = _uniform(rng, d.start_s), _uniform(rng, d.duration_s)
        pool = list(d.pool if d.pool is not None else ids)
        order = [pool[j] for j in rng.permutation(len(pool))]
        params = {k: _uniform(rng, v) for k, v in sorted(d.params.items())}
        if not hit:
            continue
        fault: dict[str, Any] = {"name": f"draw{i}-{d.kind}", "kind": d.kind, "start_s": float(start),
                                 "duration_s": float(duration), **params}
        if d.kind in TARGETED:
            fault["targets"] = sorted(order[:d.targets])
        elif d.kind == "link_partition":
            fault["groups"] = [sorted(order[g::d.groups]) for g in range(d.groups)]
        out.append(fault)
    return out


def with_drawn_faults(sc: Scenario, drawn: list[dict[str, Any]]) -> Scenario:
    """The scenario with the drawn faults added to its own `[[fault]]` tables, validated again as a
    whole (deploy/scenario.py), so a drawn fault that does not fit the scenario is a ScenarioError."""
    doc = copy.deepcopy(sc.doc)
    doc["fault"] = [*doc.get("fault", []), *drawn]
    out = parse_scenario(doc, sc.source)
    out.sets = sc.sets
    return out
