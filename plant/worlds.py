"""The plant's truth models ("worlds"), registered by fidelity (issue 25: no branch of `PlantNode`
names a mission's truth model).

A world holds the translational (and, for bodies, attitude) state of every spacecraft, the actuator
model and the delta-v accounting; it propagates with the propagator its fidelity names
(plant/dynamics/propagator.py). Each world module registers a factory `(PlantConfig) -> world` for
the fidelities it flies: plant/world.py the ROE world of paper 002 (`linear`, `j2`: LVLH
propagators, truth with ROE), plant/mission_world.py the Cartesian world with bodies and attitude
(`cw`, `inertial`). `make_world(config)` looks the fidelity up; plant/node.py imports both modules.
Nothing of the project is imported here, so a world module can import it.
"""
from __future__ import annotations

from typing import Any, Callable

WorldFactory = Callable[[Any], Any]  # (plant.config.PlantConfig) -> World | MissionWorld
_WORLDS: dict[str, WorldFactory] = {}


def register_world(*fidelities: str) -> Callable[[WorldFactory], WorldFactory]:
    """Register `factory(config)` as the world of each of `fidelities`."""
    def deco(factory: WorldFactory) -> WorldFactory:
        for f in fidelities:
            if f in _WORLDS and _WORLDS[f] is not factory:
                raise ValueError(f"fidelity {f!r} already has a world ({_WORLDS[f].__qualname__})")
            _WORLDS[f] = factory
        return factory

    return deco


def world_fidelities() -> list[str]:
    return sorted(_WORLDS)


def make_world(config: Any) -> Any:
    """The world of `config.fidelity`, built from the plant's configuration."""
    factory = _WORLDS.get(config.fidelity)
    if factory is None:
        raise ValueError(f"no plant world flies fidelity {config.fidelity!r}; known: {world_fidelities()}")
    return factory(config)
