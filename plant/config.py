"""What the plant is configured with: `PlantConfig`, a frozen, typed distillation of a scenario.

The plant (plant/node.py, its worlds, sensing kinds, faults and contact monitor) reads this and
nothing else of a scenario; deploy/scenario.py `plant_config(sc)` builds it from the validated
Scenario (the plant never imports deploy). It is the plant's counterpart of the agent's
`agent_config` (deploy/agent_image.py). Every value is the one the Scenario holds (same floats, same
validated spec objects), so the truth a plant computes from it is the Scenario's, bit for bit
(tests/test_truth_checksums.py; bench/truth_checksums.py before and after on one machine).

Frozen: the dataclasses are frozen, every table is a read-only mapping (`freeze`: dicts become
`MappingProxyType`, lists tuples, all the way down), `roe_m` a read-only array, and the specs are
frozen pydantic models (plant/bodies.py, plant/faults.py, plant/contact.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Literal, Mapping

import numpy as np

from swarmhil.plant.bodies import BodySpec, SpacecraftSpec
from swarmhil.plant.contact import ContactConfig


def freeze(value: Any) -> Any:
    """A read-only copy of JSON-like data: dicts -> MappingProxyType, lists and tuples -> tuples."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: freeze(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(freeze(v) for v in value)
    return value


@dataclass(frozen=True)
class PlantOrbit:
    """The reference orbit ([orbit]); `mean_motion_radps` as the scenario computed it."""

    semi_major_axis_m: float
    inclination_rad: float
    raan_rad: float
    u0_rad: float                 # argument of latitude at t = 0 (argp + true anomaly)
    mean_motion_radps: float
    eccentricity: float = 0.0     # fidelity "inertial" only
    argp_rad: float = 0.0


@dataclass(frozen=True)
class PlantConfig:
    """Everything the plant process is configured with (one run)."""

    ids: tuple[str, ...]                      # spacecraft ids, in the order of every (N, ...) array
    steps: int                                # steps of the run (duration / step)
    step_s: float
    seed: int                                 # [run].seed: every sensing and fault draw
    mode: Literal["lockstep", "realtime"]
    speed: float                              # realtime: simulated seconds per wall second
    stall_timeout_s: float                    # lockstep: the wall time a missing command is waited for
    orbit: PlantOrbit
    fidelity: str                             # linear | j2 (plant/world.py) | cw | inertial (plant/mission_world.py)
    drag: Mapping[str, Any] | None            # j2 fidelity's drag table
    max_accel_mps2: float                     # the swarm's actuator limit (a spacecraft's own overrides it)
    actuator_limit: str                       # per_axis | norm
    plant_options: Mapping[str, Any]          # [plant]: frame_origin, j2, atmospheric_drag, command_frame, ...
    roe_m: np.ndarray                         # (N, 6) initial ROE of each spacecraft (read-only)
    spacecraft: tuple[SpacecraftSpec, ...]    # one per id
    bodies: tuple[BodySpec, ...]              # [[body]]: targets, debris
    camera: Mapping[str, float]               # [camera]: the camera sensing kinds' geometry
    sensing: Mapping[str, Any]                # [sensing]: kind, its noise, [sensing.params]
    controllers: tuple[tuple[str, Mapping[str, Any]], ...]  # (controller, params) per id: for a sensor
    #   the flight software's parameters define (paper 004's graph, missions/p004_lbdnn/sense.py)
    faults: tuple[Any, ...] = ()              # [[fault]]: plant/faults.py specs (frozen pydantic models)
    contact: ContactConfig | None = None      # [contact]

    def controller_of(self, sc_id: str) -> tuple[str, Mapping[str, Any]]:
        """(controller name, params) of one spacecraft, as its flight software is configured."""
        return self.controllers[self.ids.index(sc_id)]
