"""Faults as scenario data (issue 27): the `[[fault]]` schedule, and the plant-side faults.

A `[[fault]]` table names a `kind`, a window in simulated time (`start_s`, and `end_s` or
`duration_s`; neither: until the end of the run) and what it strikes (`targets`: spacecraft ids;
`groups` / `between`: sets of spacecraft for the link). Validated once at scenario load (pydantic,
closed models, one-line errors naming the table and field, as plant/bodies.py); docs/faults.md
lists every kind, where it acts and what the flight software can see of it.

Time: a fault is active at step k when start_s <= t_k < end_s, evaluated once as step indices
(`FaultWindow`), so every process (plant, link channel, launcher) agrees on the steps and a
lockstep run with faults is bit for bit the same on rerun.

Where each family acts:
- actuation (`thruster_*`): in the plant's actuator model, on the acceleration the limiter lets
  through (`ActuationFaults`, called by plant/world.py and plant/mission_world.py);
- sensing (`sensor_*`): in the plant, on the stimulus message of the struck spacecraft, after the
  sensing kind made it (`SensingFaults`); the flight software sees only the changed stimulus;
- link (`link_*`): in the link channel (link/faults.py);
- process (`process_*`): by the launcher, at a simulated step (deploy/launcher.py);
- body (`body_*`): in the mission world's bodies (plant/mission_world.py): a manoeuvre of a
  propagated body is added to its dynamics, a kinematic body's pose is integrated in closed form
  over the window (`kinematic_pose`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from swarmhil.plant.bodies import format_validation_error

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
IdList = Annotated[list[str], Field(min_length=1)]
STEP_TOL = 1e-9  # a start or end within this fraction of a step of a step time falls on that step


class _Fault(BaseModel):
    """Fields every fault has: an optional name, its window in simulated seconds."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    name: str | None = None                 # default: "fault<i>" (its index in the file)
    start_s: float = Field(0.0, ge=0)
    end_s: float | None = None              # exclusive; omitted (with duration_s): until the run ends
    duration_s: float | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _window(self) -> "_Fault":
        if self.end_s is not None and self.duration_s is not None:
            raise ValueError("give end_s or duration_s, not both")
        if self.end_s is not None and self.end_s <= self.start_s:
            raise ValueError(f"end_s {self.end_s} must be after start_s {self.start_s}")
        return self

    @property
    def stop_s(self) -> float:
        """End of the window (inf: until the run ends)."""
        if self.end_s is not None:
            return float(self.end_s)
        if self.duration_s is not None:
            return float(self.start_s + self.duration_s)
        return math.inf

    @property
    def family(self) -> str:
        return self.kind.split("_", 1)[0]  # type: ignore[attr-defined]

    def spacecraft(self) -> list[str]:
        """Every spacecraft id the fault names (to check them against the scenario)."""
        ids: list[str] = list(getattr(self, "targets", []) or [])
        for g in getattr(self, "groups", None) or []:
            ids += g
        for g in getattr(self, "between", None) or []:
            ids += g
        return ids


class _Targeted(_Fault):
    targets: IdList                         # spacecraft ids


class ThrusterStuckOff(_Targeted):
    """The thrusters give nothing: applied acceleration 0 whatever is commanded."""

    kind: Literal["thruster_stuck_off"]


class ThrusterStuckOn(_Targeted):
    """The thrusters give `accel_mps2` (command frame) whatever is commanded, alive or not."""

    kind: Literal["thruster_stuck_on"]
    accel_mps2: Vec3


class ThrusterEfficiency(_Targeted):
    """The applied acceleration is `factor` times what the limiter lets through."""

    kind: Literal["thruster_efficiency"]
    factor: float = Field(ge=0)


class ThrusterMisaligned(_Targeted):
    """The applied acceleration is turned by `angle_deg` about `axis` (command frame; right hand)."""

    kind: Literal["thruster_misaligned"]
    angle_deg: float
    axis: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 1.0])

    @model_validator(mode="after")
    def _axis(self) -> "ThrusterMisaligned":
        if not any(self.axis):
            raise ValueError("axis must not be zero")
        return self


class SensorDropout(_Targeted):
    """The stimulus comes every step but empty: no neighbours, bodies or measurements."""

    kind: Literal["sensor_dropout"]


class SensorBias(_Targeted):
    """Every sensed relative position gets + bias_m (velocity + bias_mps), in the stimulus's frame."""

    kind: Literal["sensor_bias"]
    bias_m: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    bias_mps: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])


class SensorNoise(_Targeted):
    """The sensing kind's own error on relative states times `factor`, plus white Gaussian noise
    of `position_sigma_m` / `velocity_sigma_mps` per axis (seeded by run seed, fault, step, observer)."""

    kind: Literal["sensor_noise"]
    factor: float = Field(1.0, ge=0)
    position_sigma_m: float = Field(0.0, ge=0)
    velocity_sigma_mps: float = Field(0.0, ge=0)


class SensorFrozen(_Targeted):
    """The stimulus of the fault's first step is sent again every step (stale), with a new header."""

    kind: Literal["sensor_frozen"]


class LinkPartition(_Fault):
    """Packets between spacecraft of different `groups` are dropped (ids in no group form one more)."""

    kind: Literal["link_partition"]
    groups: Annotated[list[IdList], Field(min_length=1)]


class LinkDegraded(_Fault):
    """Links between the two sets of `between` (both ways; default: every link) lose packets with
    `loss_probability` more, and deliver `extra_latency_s` later."""

    kind: Literal["link_degraded"]
    between: Annotated[list[IdList], Field(min_length=2, max_length=2)] | None = None
    loss_probability: float = Field(0.0, ge=0, le=1)
    extra_latency_s: float = Field(0.0, ge=0)


class _BodyTargeted(_Fault):
    bodies: IdList                          # [[body]] ids


class BodyManoeuvre(_BodyTargeted):
    """The bodies accelerate by `accel_mps2` (scenario frame) over the window: added to a propagated
    body's dynamics, integrated in closed form for a kinematic one (a target's manoeuvre)."""

    kind: Literal["body_manoeuvre"]
    accel_mps2: Vec3


class BodySpin(_BodyTargeted):
    """Kinematic bodies spin at `spin_rate_radps` about `spin_axis` (scenario frame; default: their
    own axis) over the window, then at their own rate again (a target's spin change)."""

    kind: Literal["body_spin"]
    spin_rate_radps: float
    spin_axis: Vec3 | None = None

    @model_validator(mode="after")
    def _axis(self) -> "BodySpin":
        if self.spin_axis is not None and not any(self.spin_axis):
            raise ValueError("spin_axis must not be zero")
        return self


class ProcessCrash(_Targeted):
    """The flight software of `targets` is killed at start_s (SIGKILL by the launcher); it restarts or
    not per [supervision]."""

    kind: Literal["process_crash"]


class ProcessPause(_Targeted):
    """The flight software of `targets` is frozen (SIGSTOP) over the window, then resumes (SIGCONT)."""

    kind: Literal["process_pause"]


MODELS: dict[str, type[_Fault]] = {
    m.model_fields["kind"].annotation.__args__[0]: m  # type: ignore[union-attr]
    for m in (ThrusterStuckOff, ThrusterStuckOn, ThrusterEfficiency, ThrusterMisaligned, SensorDropout, SensorBias,
              SensorNoise, SensorFrozen, LinkPartition, LinkDegraded, ProcessCrash, ProcessPause, BodyManoeuvre,
              BodySpin)}
KINDS = tuple(sorted(MODELS))


class FaultError(ValueError):
    """A bad [[fault]] table; the message is one line naming the file, the table and the field."""


def parse_faults(src: str, items: Any, ids: list[str], step_s: float,
                 bodies: dict[str, str] | None = None) -> list[Any]:
    """Validate the `[[fault]]` tables of a scenario against its spacecraft ids, its bodies
    ({[[body]] id: motion kind}) and its step."""
    if not isinstance(items, list):
        raise FaultError(f"{src}: [[fault]] must be an array of tables (got {items!r})")
    known = set(ids)
    out: list[Any] = []
    names: set[str] = set()
    for i, item in enumerate(items):
        where = f"[[fault]][{i}]"
        if not isinstance(item, dict):
            raise FaultError(f"{src}: {where} must be a table (got {item!r})")
        if "kind" not in item:
            raise FaultError(f"{src}: {where}.kind is required; known: {list(KINDS)}")
        if item["kind"] not in KINDS:
            raise FaultError(f"{src}: {where}.kind is not a known fault kind; known: {list(KINDS)} "
                             f"(got {item['kind']!r})")
        model = MODELS[item["kind"]]
        try:
            f = model.model_validate(item)
        except ValidationError as exc:
            raise FaultError(_one_line(src, where, exc, model)) from None
        for sid in f.spacecraft():
            if sid not in known:
                raise FaultError(f"{src}: {where} names unknown spacecraft id {sid!r}; known: {_some(ids)}")
        for bid in getattr(f, "bodies", ()):
            motion = (bodies or {}).get(bid)
            if motion is None:
                raise FaultError(f"{src}: {where} names unknown body id {bid!r}; known [[body]] ids: "
                                 f"{_some(sorted(bodies or {}))}")
            if isinstance(f, BodySpin) and motion != "kinematic":
                raise FaultError(f"{src}: {where}: body_spin needs a kinematic body; {bid!r} is {motion}")
        if isinstance(f, LinkPartition):
            flat = [s for g in f.groups for s in g]
            dup = sorted({s for s in flat if flat.count(s) > 1})
            if dup:
                raise FaultError(f"{src}: {where}.groups puts {dup[0]!r} in more than one group")
        if isinstance(f, LinkDegraded) and f.between and set(f.between[0]) & set(f.between[1]):
            raise FaultError(f"{src}: {where}.between: the two sets share {sorted(set(f.between[0]) & set(f.between[1]))}")
        name = f.name or f"fault{i}"
        if name in names:
            raise FaultError(f"{src}: {where}.name is a duplicate (got {name!r})")
        names.add(name)
        if f.name is None:
            f = f.model_copy(update={"name": name})
        w = FaultWindow.of(f, step_s)
        if w.stop_step <= w.start_step:
            raise FaultError(f"{src}: {where} lasts less than one step of {step_s} s "
                             f"(start_s {f.start_s}, end {f.stop_s})")
        out.append(f)
    return out


def _one_line(src: str, where: str, exc: ValidationError, model: type[BaseModel]) -> str:
    """plant/bodies.py's one-line error, without the whole table as the value of a table-level error."""

    whole = [e for e in exc.errors() if not e["loc"]]
    if whole:
        return f"{src}: {where} {whole[0]['msg'].removeprefix('Value error, ')}"
    return format_validation_error(src, where, exc, model)


def _some(ids: list[str], n: int = 8) -> str:
    return str(ids[:n])[:-1] + (", ...]" if len(ids) > n else "]")


# --- windows in steps -------------------------------------------------------------------------------
BIG_STEP = 2**62  # the stop step of a fault that lasts until the run ends


@dataclass(frozen=True)
class FaultWindow:
    """A fault's window as step indices: active at step k when start_step <= k < stop_step."""

    start_step: int
    stop_step: int

    @staticmethod
    def of(fault: Any, step_s: float) -> "FaultWindow":
        """First step whose time t_k = k step_s is >= start_s; first step >= the end (t_k >= end_s)."""
        k0 = math.ceil(fault.start_s / step_s - STEP_TOL)
        stop = fault.stop_s
        k1 = BIG_STEP if math.isinf(stop) else math.ceil(stop / step_s - STEP_TOL)
        return FaultWindow(int(k0), int(k1))

    def active(self, step: int) -> bool:
        return self.start_step <= step < self.stop_step


def fault_summary(fault: Any) -> dict[str, Any]:
    """What an event and a report say of a fault: its table as validated, with its end resolved."""
    d = fault.model_dump(exclude_none=True)
    d["end_s"] = None if math.isinf(fault.stop_s) else fault.stop_s
    d.pop("duration_s", None)
    return d


def transitions(faults: list[Any], step_s: float, step: int, final: bool) -> list[tuple[str, Any]]:
    """("fault_start" | "fault_end", fault) of the faults that start or end at `step`; at the final
    step (`final`: the run ends here) every fault still active ends."""
    out: list[tuple[str, Any]] = []
    for f in faults:
        w = FaultWindow.of(f, step_s)
        if w.start_step == step and not final:
            out.append(("fault_start", f))
        elif w.stop_step == step or (final and w.start_step < step < w.stop_step):
            out.append(("fault_end", f))
    return out


# --- actuation (pure functions over the (N, 3) applied accelerations) ------------------------------
def rotation_matrix(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues' rotation formula: R = I + sin(a) K + (1 - cos(a)) K^2, K the cross matrix of the unit axis."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle_rad) * kx + (1.0 - math.cos(angle_rad)) * (kx @ kx)


def apply_actuation_fault(fault: Any, accel_mps2: np.ndarray, rows: np.ndarray) -> None:
    """Change, in place, the applied accelerations (N, 3) of the spacecraft `rows` as `fault` does."""
    if isinstance(fault, ThrusterStuckOff):
        accel_mps2[rows] = 0.0
    elif isinstance(fault, ThrusterStuckOn):
        accel_mps2[rows] = np.asarray(fault.accel_mps2, float)
    elif isinstance(fault, ThrusterEfficiency):
        accel_mps2[rows] *= fault.factor
    elif isinstance(fault, ThrusterMisaligned):
        accel_mps2[rows] = accel_mps2[rows] @ rotation_matrix(np.asarray(fault.axis), math.radians(fault.angle_deg)).T


ACTUATION = (ThrusterStuckOff, ThrusterStuckOn, ThrusterEfficiency, ThrusterMisaligned)
BODY = (BodyManoeuvre, BodySpin)
SENSING = (SensorDropout, SensorBias, SensorNoise, SensorFrozen)


class ActuationFaults:
    """The plant's actuator faults: called with the accelerations the limiter let through at step k."""

    def __init__(self, faults: list[Any], ids: list[str], step_s: float) -> None:
        index = {s: i for i, s in enumerate(ids)}
        self.items = [(FaultWindow.of(f, step_s), f, np.array([index[s] for s in f.targets], dtype=np.int64))
                      for f in faults if isinstance(f, ACTUATION)]

    def __bool__(self) -> bool:
        return bool(self.items)

    def __call__(self, accel_mps2: np.ndarray, step: int) -> np.ndarray:
        """The applied accelerations of step `step` (a new array when a fault is active)."""
        active = [(f, rows) for w, f, rows in self.items if w.active(step)]
        if not active:
            return accel_mps2
        a = np.array(accel_mps2, dtype=float)
        for f, rows in active:
            apply_actuation_fault(f, a, rows)
        return a


# --- sensing (on the stimulus message) ---------------------------------------------------------------
def _vec(v: Any) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def _set(v: Any, x: np.ndarray) -> None:
    v.x, v.y, v.z = (float(c) for c in x)


class SensingFaults:
    """The plant's sensing faults: `apply(stim, j, ctx)` changes the stimulus of spacecraft j at
    ctx.step. Acts on what every stimulus type reports of others: `neighbours` (relative LVLH
    position and velocity: RelStimulus, Measurements) and `bodies` (camera-frame poses:
    SceneStimulus). Named measurement items are cleared by a dropout and frozen with the rest, and
    otherwise left as the sensing kind made them."""

    def __init__(self, faults: list[Any], ids: list[str], step_s: float, seed: int) -> None:
        self.ids = list(ids)
        self.seed = int(seed)
        self.items = [(k, FaultWindow.of(f, step_s), f, {s for s in f.targets})
                      for k, f in enumerate(faults) if isinstance(f, SENSING)]
        self._frozen: dict[tuple[int, int], Any] = {}  # (fault index, observer) -> the stale stimulus

    def __bool__(self) -> bool:
        return bool(self.items)

    def apply(self, stim: Any, j: int, ctx: Any) -> Any:
        sid = self.ids[j]
        for k, w, f, targets in self.items:
            if sid not in targets or not w.active(ctx.step):
                continue
            if isinstance(f, SensorFrozen):
                stim = self._freeze(k, j, stim, ctx.step == w.start_step)
            elif isinstance(f, SensorDropout):
                for name in ("neighbours", "bodies", "items"):
                    if name in stim.DESCRIPTOR.fields_by_name:
                        stim.ClearField(name)
            elif isinstance(f, SensorBias):
                self._shift(stim, np.asarray(f.bias_m, float), np.asarray(f.bias_mps, float))
            elif isinstance(f, SensorNoise):
                self._noise(stim, f, k, j, ctx)
        return stim

    def _freeze(self, k: int, j: int, stim: Any, first: bool) -> Any:
        if first or (k, j) not in self._frozen:
            self._frozen[(k, j)] = stim.__class__.FromString(stim.SerializeToString())
            return stim
        stale = stim.__class__()
        stale.CopyFrom(self._frozen[(k, j)])
        stale.header.CopyFrom(stim.header)
        return stale

    @staticmethod
    def _shift(stim: Any, dp: np.ndarray, dv: np.ndarray) -> None:
        for nb in getattr(stim, "neighbours", ()):
            _set(nb.position_m, _vec(nb.position_m) + dp)
            _set(nb.velocity_mps, _vec(nb.velocity_mps) + dv)
        for b in getattr(stim, "bodies", ()):
            _set(b.position_cam_m, _vec(b.position_cam_m) + dp)

    def _noise(self, stim: Any, f: SensorNoise, k: int, j: int, ctx: Any) -> None:
        """Relative states: truth + factor (sensed - truth) + white noise (only neighbours carry truth)."""
        neighbours = getattr(stim, "neighbours", None)
        if not neighbours:
            return
        rng = np.random.default_rng([self.seed, 0xFA17, k, int(ctx.step), j])
        index = {s: i for i, s in enumerate(ctx.ids)}
        pos, vel = ctx.position_m, ctx.velocity_mps
        for nb in neighbours:
            i = index.get(nb.id)
            if i is None:
                continue
            tp, tv = pos[i] - pos[j], vel[i] - vel[j]
            p = tp + f.factor * (_vec(nb.position_m) - tp) + rng.normal(0.0, 1.0, 3) * f.position_sigma_m
            v = tv + f.factor * (_vec(nb.velocity_mps) - tv) + rng.normal(0.0, 1.0, 3) * f.velocity_sigma_mps
            _set(nb.position_m, p)
            _set(nb.velocity_mps, v)


# --- bodies (in the mission world) -------------------------------------------------------------------
@dataclass(frozen=True)
class BodyFault:
    """A body fault as a window in simulated seconds [t0_s, t1_s) on its step grid (FaultWindow)."""

    fault: Any
    t0_s: float
    t1_s: float
    window: "FaultWindow"


def body_faults(faults: list[Any], step_s: float) -> dict[str, list[BodyFault]]:
    """{body id: its body faults}, windows turned into the times of their first and stop steps."""
    out: dict[str, list[BodyFault]] = {}
    for f in faults:
        if isinstance(f, BODY):
            w = FaultWindow.of(f, step_s)
            t1 = math.inf if w.stop_step >= BIG_STEP else w.stop_step * step_s
            for bid in f.bodies:
                out.setdefault(bid, []).append(BodyFault(f, w.start_step * step_s, t1, w))
    return out


def manoeuvre_displacement(accel_mps2: np.ndarray, t0_s: float, t1_s: float, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(position, velocity) added by a constant acceleration over [t0, t1) by time t (closed form):
    ½ a (t - t0)² inside the window, then ½ a T² + a T (t - t1) with T = t1 - t0."""
    a = np.asarray(accel_mps2, float)
    if t_s <= t0_s:
        return np.zeros(3), np.zeros(3)
    if t_s <= t1_s:
        d = t_s - t0_s
        return 0.5 * a * d * d, a * d
    T = t1_s - t0_s
    return 0.5 * a * T * T + a * T * (t_s - t1_s), a * T


def spin_segments(axis: np.ndarray, rate_radps: float, faults: list[BodyFault], t_s: float
                  ) -> list[tuple[np.ndarray, float, float]]:
    """The body's spin from 0 to t as time-ordered (axis, rate, duration) segments: its own spin,
    replaced by a body_spin fault's over that fault's window (the one that started last wins)."""
    spins = [bf for bf in faults if isinstance(bf.fault, BodySpin)]
    cuts = sorted({0.0, t_s, *(x for bf in spins for x in (bf.t0_s, bf.t1_s) if 0.0 < x < t_s)})
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        live = [bf for bf in spins if bf.t0_s <= a < bf.t1_s]
        if live:
            f = max(live, key=lambda bf: bf.t0_s).fault
            ax = np.asarray(f.spin_axis if f.spin_axis is not None else axis, float)
            out.append((ax / np.linalg.norm(ax), float(f.spin_rate_radps), b - a))
        else:
            out.append((np.asarray(axis, float), float(rate_radps), b - a))
    return out
