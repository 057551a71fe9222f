"""The sensing-kind registry and the per-step context every kind reads (plant/sensing/__init__.py)."""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np
from google.protobuf.message import Message

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.discovery import import_all, import_role
from swarmhil.plant.config import PlantConfig


@dataclass
class SensingContext:
    """Truth at step k, shared by every observer of the step (computed once; `cache` for per-step
    products such as a visibility matrix)."""

    step: int
    t_s: float
    u_rad: float
    ids: list[str]
    position_m: np.ndarray       # (N,3) scenario frame
    velocity_mps: np.ndarray     # (N,3)
    alive: np.ndarray            # (N,) bool
    world: Any                   # World or MissionWorld (bodies, attitude where flown)
    cache: dict[str, Any] = field(default_factory=dict)
    all_alive: bool = False      # True: the maker knows every `alive` is (False: look at `alive`)

    def cached(self, name: str, make: Callable[[], Any]) -> Any:
        if name not in self.cache:
            self.cache[name] = make()
        return self.cache[name]


def keyed_rng(*key: int) -> np.random.Generator:
    """`np.random.default_rng(list(key))`: the generator of one observer's draws at one step, keyed
    (seed, tag, step, observer) so that the draws do not depend on who asks first. A key of
    non-negative integers below 2**32 is handed over as the uint32 array the list becomes inside
    numpy's SeedSequence (each such integer one word: `_coerce_to_uint32_array`), the same stream
    without the list's conversion, word by word in Python (about a third of the generator's
    making); other keys go as the list (tests/test_sensing_rng.py)."""
    if key and 0 <= min(key) and max(key) <= 0xFFFFFFFF:
        return np.random.default_rng(np.array(key, dtype=np.uint32))
    return np.random.default_rng(list(key))


class SensingKind(Protocol):
    message: type[Message]

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> Message: ...


_KINDS: dict[str, Callable[[PlantConfig], SensingKind]] = {}
_VALIDATORS: dict[str, Callable[[dict[str, Any]], Any]] = {}
# modules that register kinds on import (built-ins and the missions' plant-side sensors)
_PROVIDERS = ["swarmhil.plant.sensing.builtin"]


def register_sensing(name: str, validate: Callable[[dict[str, Any]], Any] | None = None
                     ) -> Callable[[Callable[[PlantConfig], SensingKind]], Callable[[PlantConfig], SensingKind]]:
    def deco(factory: Callable[[PlantConfig], SensingKind]) -> Callable[[PlantConfig], SensingKind]:
        _KINDS[name] = factory
        if validate is not None:
            _VALIDATORS[name] = validate
        return factory

    return deco


def add_provider(module: str) -> None:
    """Name a module that registers sensing kinds when imported (a mission's plant-side sensors)."""
    if module not in _PROVIDERS:
        _PROVIDERS.append(module)


def _load() -> None:
    """Import the providers, every module of this package (the built-in kinds), and every mission
    room's sensing kind, missions/<room>/sense (bus/discovery.py `import_role`; a kind registers by
    decorator: nothing else is edited)."""
    for m in list(_PROVIDERS):
        importlib.import_module(m)
    import_all("swarmhil.plant.sensing", skip=("registry",))
    import_role("sense")


def known_sensing() -> list[str]:
    _load()
    return sorted(_KINDS)


def validate_sensing_params(kind: str, params: dict[str, Any]) -> None:
    _load()
    check = _VALIDATORS.get(kind)
    if check is not None:
        check(dict(params))
    elif params:
        raise ValueError(f"sensing kind {kind!r} takes no [sensing.params] (got {sorted(params)})")


def make_sensing(kind: str, scenario: PlantConfig) -> SensingKind:
    _load()
    if kind not in _KINDS:
        raise ValueError(f"unknown sensing kind {kind!r}; known: {sorted(_KINDS)}")
    return _KINDS[kind](scenario)


def has_batch_form(kind: str) -> bool:
    """Whether the kind also gives every observer's stimulus at once as arrays (`batch(ctx, observers)`,
    the batch mode of issue 16), without building one."""
    _load()
    return hasattr(_KINDS.get(kind), "batch")


def sensing_message(kind: str) -> Any:
    """The message class a kind publishes (its `message`), or None for an unknown kind."""
    _load()
    return getattr(_KINDS.get(kind), "message", None)
