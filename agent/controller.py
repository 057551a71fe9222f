"""The one small interface every flight-software controller implements.

A controller is a pure object over numpy arrays: it is given what the agent knows at a step
(`Observation`) and returns the acceleration it commands (`Command`). It never sees truth it
could not have measured, and never touches the bus: the agent process loop does the I/O.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

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
    isl_rx: list[Any] = field(default_factory=list)  # IslPacket messages received since the last step


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
    name: str

    def step(self, obs: Observation) -> Command: ...


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


def load_controllers() -> None:
    """Import the built-in controllers and every mission package under agent/missions/ (each
    registers its controllers by decorator when imported: adding a mission edits nothing here).
    Lazy, because the missions import this module for `register`."""
    from agent import controllers  # noqa: F401  (registers the built-in controllers)
    from agent.missions import load_missions

    load_missions()


def validate_params(name: str, params: dict[str, Any]) -> None:
    """Check a controller's params with its registered validator (no-op when it has none)."""
    load_controllers()

    check = _VALIDATORS.get(name)
    if check is not None:
        check(dict(params))


def make_controller(name: str, sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> Controller:
    load_controllers()

    if name not in _REGISTRY:
        raise ValueError(f"unknown controller {name!r}; known: {sorted(_REGISTRY)}")
    return _REGISTRY[name](sc_id, orbit, params)


def known_controllers() -> list[str]:
    load_controllers()

    return sorted(_REGISTRY)
