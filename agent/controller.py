"""The one small interface every flight-software controller implements.

A controller is a pure object over numpy arrays: it is given what the agent knows at a step
(`Observation`) and returns the acceleration it commands (`Command`). It never sees truth it
could not have measured, and never touches the bus: the agent process loop does the I/O.

A controller module registers its factory here by name (`register`); this module discovers nothing
and imports no controller: agent/catalogue.py, above every controller, loads them on demand and
makes a scenario's controller (`make_controller`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol, Sequence

import numpy as np


@dataclass(frozen=True)
class OrbitInfo:
    """What the flight software knows of the reference orbit (from the scenario / ground)."""

    semi_major_axis_m: float
    mean_motion_radps: float


@dataclass
class Observation:
    """What an agent knows at step k.

    `rel_position_m` / `rel_velocity_mps` are (N, 3) LVLH states of neighbour k relative to this
    spacecraft j (r_k - r_j), one row per entry of `neighbour_ids`.
    """

    step: int
    t_s: float
    u_rad: float
    neighbour_ids: list[str]
    rel_position_m: np.ndarray
    rel_velocity_mps: np.ndarray
    extra: dict[str, Any] = field(default_factory=dict)
    isl_rx: list[Any] = field(default_factory=list)  # IslPacket messages received since the last step (batch mode: deploy/batch.py RxPacket, their fields)


def decode_once(cache: dict[tuple[str, bytes], Any] | None, pkt: Any, decode: Callable[[bytes], Any]) -> Any:
    """decode(pkt.payload), looked up in `cache` first (None: no cache) and kept there: a batch
    path's flight software decodes each broadcast once a step for all its receivers (issue 29),
    into values nobody modifies, so each receiver reads what its own decode would give."""
    if cache is None:
        return decode(pkt.payload)
    key = (pkt.type, pkt.payload)
    got = cache.get(key)
    if got is None:
        got = cache[key] = decode(pkt.payload)
    return got


@dataclass
class Decision:
    """One neighbour's behaviour decision, for telemetry."""

    neighbour: str
    behaviour: str
    d_min_m: float
    roe_rel_m: np.ndarray
    accel_mps2: np.ndarray


@dataclass
class Transmission:
    """An inter-satellite-link packet to send (through the channel, link/node.py)."""

    type: str
    payload: bytes
    dst: str = ""  # empty: broadcast to everyone in range


@dataclass
class Command:
    """What a controller commands for the next step.

    `accel_mps2` is the LVLH acceleration; `torque_nm` the body-frame control torque, for
    controllers that fly attitude too (None: no attitude command, the plant holds none).
    `extra` holds named arrays (e.g. the controller's estimates) that go out in the step's
    telemetry as `Telemetry.items` (read back with `bus.codec.measurements_to_dict`).
    """

    accel_mps2: np.ndarray
    mode: str = "idle"
    decisions: list[Decision] = field(default_factory=list)
    transmissions: list[Transmission] = field(default_factory=list)
    torque_nm: np.ndarray | None = None  # body-frame torque, where the scenario flies attitude
    extra: dict[str, np.ndarray] = field(default_factory=dict)  # named arrays for telemetry (Telemetry.items)


class Controller(Protocol):
    """Per spacecraft: `step(obs) -> Command`. A controller class may also define a classmethod
    `step_batch(controllers, batch) -> CommandBatch` that decides for many spacecraft at once
    (issue 16: N = 1 in an agent process, N = 20 in a batch run); `step_batch` below calls it, and
    otherwise each controller's `step` in turn. A batch path must give each spacecraft the command
    its own `step` gives, bit for bit (so batch and multi-process runs keep one truth). A class
    whose command never depends on the observation may set `observes = False`: a batch run then
    hands it observations without neighbours instead of computing the stimuli (deploy/batch.py)."""

    name: str

    def step(self, obs: Observation) -> Command: ...


@dataclass
class ObservationBatch:
    """What N agents know at the same step: every observer's neighbours concatenated (CSR rows).

    Observer i's neighbours are rows offsets[i]:offsets[i + 1] of `neighbour_ids`,
    `rel_position_m` and `rel_velocity_mps` ((P, 3): r_k - r_j in LVLH, as in `Observation`).
    """

    step: int
    t_s: float
    u_rad: float
    observers: list[str]
    offsets: np.ndarray  # (N + 1,) int
    neighbour_ids: list[str]
    rel_position_m: np.ndarray
    rel_velocity_mps: np.ndarray
    extra: Sequence[dict[str, Any]] | None = None  # per observer (None: all empty; bus.codec.NamedRows: as arrays)
    isl_rx: list[list[Any]] | None = None  # per observer (None: nothing received)
    owner: np.ndarray | None = None  # (P,) the observer (row) of each neighbour row, when the maker has it

    def owners(self) -> np.ndarray:
        """(P,) the observer of each neighbour row: `owner`, else from `offsets`."""
        if self.owner is not None:
            return self.owner
        off = np.asarray(self.offsets, dtype=np.int64)
        return np.repeat(np.arange(len(self.observers)), off[1:] - off[:-1])

    def __len__(self) -> int:
        return len(self.observers)

    def observation(self, i: int) -> Observation:
        """Observer i's own Observation (views of the batch arrays)."""
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        return Observation(step=self.step, t_s=self.t_s, u_rad=self.u_rad, neighbour_ids=self.neighbour_ids[a:b],
                           rel_position_m=self.rel_position_m[a:b], rel_velocity_mps=self.rel_velocity_mps[a:b],
                           extra=self.extra[i] if self.extra is not None else {},
                           isl_rx=self.isl_rx[i] if self.isl_rx is not None else [])

    def subset(self, rows: Sequence[int]) -> "ObservationBatch":
        """The batch of the observers `rows` alone: what `of` makes of their observations (the same
        values: their neighbour rows gathered in order, their extra and packets), from the arrays."""
        off = self.offsets
        if not np.any(off):  # no neighbour rows at all (paper 003's and 004's kinds): every count 0
            sel: list[int] = []
            offsets = np.zeros(len(rows) + 1, dtype=np.int64)
        else:
            sel = [k for i in rows for k in range(int(off[i]), int(off[i + 1]))]
            offsets = np.concatenate(([0], np.cumsum([int(off[i + 1]) - int(off[i]) for i in rows]))).astype(np.int64)
        idx = np.array(sel, dtype=np.int64)
        return ObservationBatch(step=self.step, t_s=self.t_s, u_rad=self.u_rad, observers=[self.observers[i] for i in rows],
                                offsets=offsets,
                                neighbour_ids=[self.neighbour_ids[k] for k in sel],
                                rel_position_m=np.asarray(self.rel_position_m, float).reshape(-1, 3)[idx],
                                rel_velocity_mps=np.asarray(self.rel_velocity_mps, float).reshape(-1, 3)[idx],
                                extra=[self.extra[i] if self.extra is not None else {} for i in rows],
                                isl_rx=[self.isl_rx[i] if self.isl_rx is not None else [] for i in rows])

    @classmethod
    def of(cls, observers: Sequence[str], observations: Sequence[Observation]) -> "ObservationBatch":
        """The batch of per-spacecraft observations of one step (same step, t and u)."""
        counts = [len(o.neighbour_ids) for o in observations]
        o0 = observations[0]
        return cls(step=o0.step, t_s=o0.t_s, u_rad=o0.u_rad, observers=list(observers),
                   offsets=np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
                   neighbour_ids=[s for o in observations for s in o.neighbour_ids],
                   rel_position_m=np.concatenate([np.asarray(o.rel_position_m, float).reshape(-1, 3) for o in observations]),
                   rel_velocity_mps=np.concatenate([np.asarray(o.rel_velocity_mps, float).reshape(-1, 3) for o in observations]),
                   extra=[o.extra for o in observations], isl_rx=[o.isl_rx for o in observations])


@dataclass
class DecisionRows:
    """The decisions of every command of a CommandBatch as arrays: observer i's are rows
    offsets[i]:offsets[i + 1], each a `Decision(neighbour_ids[r], labels[behaviour[r]], d_min_m[r],
    roe_rel_m[r], accel_mps2[r])`. A CommandBatch that carries them says each of its commands is its
    acceleration, mode and these decisions, nothing else (no transmissions, torque or extra arrays):
    its telemetry can be written from the arrays (deploy/batch_packets.py)."""

    offsets: np.ndarray  # (N + 1,)
    neighbour_ids: list[str]  # (P,)
    labels: tuple[str, ...]
    behaviour: np.ndarray  # (P,) index into labels
    d_min_m: np.ndarray  # (P,)
    roe_rel_m: np.ndarray  # (P, 6)
    accel_mps2: np.ndarray  # (P, 3)


@dataclass
class CommandBatch:
    """The commands of the N observers of an ObservationBatch: accelerations (N, 3) and modes, and
    each one's full `Command` (decisions, transmissions, torque) on demand (`command(i)`), which a
    run that records no telemetry never builds."""

    accel_mps2: np.ndarray  # (N, 3)
    modes: list[str]
    build: Callable[[int], Command] | None = None  # observer i -> its full Command
    torque_nm: np.ndarray | None = None  # (N, 3) body-frame torques (a row of 0 for a command without one); None: none at all
    raised: tuple[int, ...] = ()  # observers whose software raised (a batch path that caught it: commanded zero, counted)
    finite: bool = False  # every acceleration (and torque) is finite: the batch path that made them checked it
    sent: Callable[[int], list[Transmission]] | None = None  # observer i -> command(i).transmissions, without the Command
    decision_rows: "DecisionRows | None" = None  # every command's decisions as arrays, where they are all it holds besides accel and mode

    def command(self, i: int) -> Command:
        if self.build is not None:
            return self.build(i)
        return Command(accel_mps2=self.accel_mps2[i].copy(), mode=self.modes[i],
                       torque_nm=None if self.torque_nm is None else self.torque_nm[i].copy())

    def transmissions(self, i: int) -> list[Transmission]:
        """Observer i's packets, `command(i).transmissions` (what the link sends every decision step,
        where a run that records no telemetry needs nothing else of the Command)."""
        return self.sent(i) if self.sent is not None else self.command(i).transmissions

    @classmethod
    def of(cls, commands: Sequence[Command]) -> "CommandBatch":
        """From per-spacecraft commands; an acceleration or torque that is not a 3-vector is a row of
        NaN, a command without a torque (None) a row of 0 (what the plant holds for it)."""
        acc = np.full((len(commands), 3), np.nan)
        tq = None
        for i, c in enumerate(commands):
            a = np.asarray(c.accel_mps2, dtype=float)
            if a.shape == (3,):
                acc[i] = a
            if c.torque_nm is not None:
                if tq is None:
                    tq = np.zeros((len(commands), 3))
                t = np.asarray(c.torque_nm, dtype=float)
                tq[i] = t if t.shape == (3,) else np.nan
        return cls(accel_mps2=acc, modes=[c.mode for c in commands], build=list(commands).__getitem__, torque_nm=tq)


def step_batch(controllers: Sequence[Controller], batch: ObservationBatch) -> CommandBatch:
    """Commands of controllers[i] for batch.observation(i), all i: through the controllers' own
    `step_batch` when they are all of one class that has one; with several classes, each class's
    `step_batch` over its own rows (a sub-batch, issue 29: paper 003's leader and servicers), and
    each `step` in turn for a class without one."""
    kinds = {type(c) for c in controllers}
    if len(kinds) == 1:
        fn = getattr(next(iter(kinds)), "step_batch", None)
        if fn is not None:
            return fn(controllers, batch)
        return CommandBatch.of([c.step(batch.observation(i)) for i, c in enumerate(controllers)])
    rows_of: dict[type, list[int]] = {}
    for i, c in enumerate(controllers):
        rows_of.setdefault(type(c), []).append(i)
    cmds: list[Command | None] = [None] * len(controllers)
    for kind, rows in rows_of.items():
        fn = getattr(kind, "step_batch", None)
        if fn is None:
            for i in rows:
                cmds[i] = controllers[i].step(batch.observation(i))
            continue
        sub = batch.subset(rows)
        cb = fn([controllers[i] for i in rows], sub)
        for k, i in enumerate(rows):
            cmds[i] = cb.command(k)
    return CommandBatch.of([c for c in cmds if c is not None])


ControllerFactory = Callable[[str, OrbitInfo, dict[str, Any]], Controller]
"""(spacecraft id, orbit, scenario `controller` params) -> controller."""

_REGISTRY: dict[str, ControllerFactory] = {}
_VALIDATORS: dict[str, Callable[[dict[str, Any]], Any]] = {}


def register(name: str, validate: Callable[[dict[str, Any]], Any] | None = None
             ) -> Callable[[ControllerFactory], ControllerFactory]:
    """Register a controller factory under `name`; `validate(params)` (optional) raises ValueError
    or TypeError naming a bad or unknown parameter, so the scenario loader rejects it at load time
    instead of every agent failing at start."""
    def deco(factory: ControllerFactory) -> ControllerFactory:
        _REGISTRY[name] = factory
        if validate is not None:
            _VALIDATORS[name] = validate
        return factory

    return deco


def registered_factory(name: str) -> ControllerFactory | None:
    """The factory registered under `name`, or None (nothing is loaded here: agent/catalogue.py loads)."""
    return _REGISTRY.get(name)


def registered_validator(name: str) -> Callable[[dict[str, Any]], Any] | None:
    return _VALIDATORS.get(name)


def registered_names() -> list[str]:
    return sorted(_REGISTRY)
