"""Typed specifications of what the plant flies: spacecraft (`[[spacecraft]]`) and bodies that are
not agents (`[[body]]`: targets, debris), validated once at scenario load (issue 11).

Pydantic v2 models, frozen and closed (`extra = "forbid"`): an unknown field is an error naming the
field and the allowed ones. Chosen over hand-written checks for its error locations
(`[[body]][0].shape.semi_axes_m`), discriminated unions (shape kinds, motion kinds) and JSON
output of the resolved configuration; msgspec would be faster, but validation happens once per run.

Conventions: positions and velocities are in the scenario's frame (the LVLH frame of the reference
orbit, x radial, y along-track, z cross-track); quaternions scalar-first (w, x, y, z), body ->
scenario frame, as in the `swarmhil.v1.Quaternion` contract.
"""
from __future__ import annotations

import math
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from swarmhil.bus.keys import check_token

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Quat = Annotated[list[float], Field(min_length=4, max_length=4)]
PROCESS_PREFIXES = ("plant", "recorder", "channel", "viz")


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def _unit_quaternion(q: list[float] | None) -> list[float] | None:
    if q is None:
        return None
    n = math.sqrt(sum(x * x for x in q))
    if not 0.5 < n < 2.0:
        raise ValueError(f"must be a unit quaternion (w, x, y, z); norm {n:.3g}")
    return [x / n for x in q]


class SpacecraftSpec(_Spec):
    """One `[[spacecraft]]` table: an agent process flies it."""

    id: str
    role: str = "agent"                     # free text: "agent", "leader", "servicer", ...
    controller: str | None = None           # default: the swarm's [controller].name
    params: dict[str, Any] = Field(default_factory=dict)  # merged over [controller.params]
    mass_kg: float = Field(10.0, gt=0)
    area_m2: float = Field(0.1, gt=0)       # drag reference area
    drag_coefficient: float = Field(2.2, ge=0)
    inertia_kgm2: Vec3 | None = None        # principal moments; attitude is flown when given
    roe_m: Annotated[list[float], Field(min_length=6, max_length=6)] | None = None
    position_m: Vec3 | None = None
    velocity_mps: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    attitude_q: Quat = Field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])
    angular_velocity_radps: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    max_accel_mps2: float | None = Field(None, gt=0)   # default: [actuator].max_accel_mps2
    max_force_n: float | None = Field(None, gt=0)      # alternative to max_accel_mps2 (divided by mass)
    limit: Literal["per_axis", "norm"] | None = None   # default: [actuator].limit
    max_torque_nm: float | None = Field(None, gt=0)    # by norm
    # "external": flight software the launcher does not start joins with the run's join kit
    # (deploy/external.py, docs/hil.md); the launcher waits join_timeout_s (default 300 s) for it.
    # (join_timeout_s is ignored for "builtin", so `--set spacecraft.N.fsw=builtin` flies it built in)
    fsw: Literal["builtin", "external"] = "builtin"
    join_timeout_s: float | None = Field(None, gt=0, le=7 * 86400)
    # the agent process's CPU budget as a fraction of one core (a flight computer slower than this
    # machine), enforced with a cgroup CPU quota where the machine allows it (deploy/cpu_budget.py)
    cpu_fraction: float | None = Field(None, ge=0.01, le=64)
    radius_m: float | None = Field(None, gt=0)         # hard-body radius (default: [contact].default_radius_m)
    # the host whose router the agent is a client of, in a run over several hosts (`swarmhil run --hosts K`,
    # `swarmhil compose --hosts h1,h2,...`: the N-th in the order given; deploy/mesh.py); default:
    # round-robin. Checked against K when the run starts (or the projects are written).
    host: int | None = Field(None, ge=0)

    @field_validator("id")
    @classmethod
    def _id_token(cls, v: str) -> str:
        check_token(v, "spacecraft id")
        if v.startswith(PROCESS_PREFIXES):
            raise ValueError(f"must not start with a process name {list(PROCESS_PREFIXES)}")
        return v

    @field_validator("attitude_q")
    @classmethod
    def _unit(cls, v: list[float]) -> list[float]:
        return _unit_quaternion(v)  # type: ignore[return-value]

    @model_validator(mode="after")
    def _one_initial_state(self) -> "SpacecraftSpec":
        if (self.roe_m is None) == (self.position_m is None):
            raise ValueError("give the initial state either as roe_m or as position_m (+ velocity_mps)")
        if self.max_accel_mps2 is not None and self.max_force_n is not None:
            raise ValueError("give max_accel_mps2 or max_force_n, not both")
        return self


class Ellipsoid(_Spec):
    kind: Literal["ellipsoid"] = "ellipsoid"
    semi_axes_m: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=3, max_length=3)]


class Spheres(_Spec):
    """A structure as a union of spheres (centres in the body frame), e.g. paper 003's ACSB."""

    kind: Literal["spheres"] = "spheres"
    centers_m: list[Vec3] = Field(min_length=1)
    radii_m: list[Annotated[float, Field(gt=0)]] = Field(min_length=1)

    @model_validator(mode="after")
    def _same_length(self) -> "Spheres":
        if len(self.centers_m) != len(self.radii_m):
            raise ValueError(f"centers_m has {len(self.centers_m)} entries, radii_m {len(self.radii_m)}")
        return self


class Manoeuvre(_Spec):
    """Constant acceleration (scenario frame) over [t_start_s, t_end_s)."""

    t_start_s: float = Field(ge=0)
    t_end_s: float
    accel_mps2: Vec3

    @model_validator(mode="after")
    def _ordered(self) -> "Manoeuvre":
        if self.t_end_s <= self.t_start_s:
            raise ValueError(f"t_end_s {self.t_end_s} must be after t_start_s {self.t_start_s}")
        return self


class Kinematic(_Spec):
    """Constant velocity and constant spin about a fixed axis (truth, not propagated)."""

    kind: Literal["kinematic"] = "kinematic"
    position_m: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    velocity_mps: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    attitude_q: Quat = Field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])
    spin_axis: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 1.0])
    spin_rate_radps: float = 0.0

    @field_validator("attitude_q")
    @classmethod
    def _unit(cls, v: list[float]) -> list[float]:
        return _unit_quaternion(v)  # type: ignore[return-value]

    @field_validator("spin_axis")
    @classmethod
    def _axis(cls, v: list[float]) -> list[float]:
        n = math.sqrt(sum(x * x for x in v))
        if n == 0:
            raise ValueError("spin_axis must not be zero")
        return [x / n for x in v]


class Propagated(_Spec):
    """Propagated by the plant's dynamics like a spacecraft, with an optional manoeuvre profile."""

    kind: Literal["propagated"] = "propagated"
    position_m: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    velocity_mps: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    manoeuvres: list[Manoeuvre] = Field(default_factory=list)


class BodySpec(_Spec):
    """One `[[body]]` table: a body in the truth that no agent flies."""

    id: str
    kind: str = "target"                    # "target", "debris", ...
    mass_kg: float = Field(1000.0, gt=0)
    area_m2: float = Field(1.0, gt=0)
    drag_coefficient: float = Field(2.2, ge=0)
    shape: Annotated[Union[Ellipsoid, Spheres], Field(discriminator="kind")] | None = None
    radius_m: float | None = Field(None, gt=0)  # hard-body sphere when no shape (default: [contact].default_radius_m)
    motion: Annotated[Union[Kinematic, Propagated], Field(discriminator="kind")] = Field(default_factory=Kinematic)

    @field_validator("id")
    @classmethod
    def _id_token(cls, v: str) -> str:
        return check_token(v, "body id")


def manoeuvre_accel(manoeuvres: list[Manoeuvre], t_s: float) -> np.ndarray:
    """Sum of the manoeuvre accelerations active at t (held over [t_start, t_end))."""
    a = np.zeros(3)
    for m in manoeuvres:
        if m.t_start_s <= t_s < m.t_end_s:
            a += np.asarray(m.accel_mps2, float)
    return a


def format_validation_error(src: str, table: str, exc: Any, model: type[BaseModel] | None = None) -> str:
    """One line: 'file: [[body]][0].shape.semi_axes_m <message> (got <value>)'; several joined by '; '."""
    lines = []
    for e in exc.errors():
        loc = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in e["loc"])
        got = e.get("input")
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "is not a known field"
            if model is not None and len(e["loc"]) == 1:
                msg += f"; known: {sorted(model.model_fields)}"
        lines.append(f"{src}: {table}{loc} {msg} (got {got!r})")
    return "; ".join(lines)
