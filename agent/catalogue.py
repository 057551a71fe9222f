"""The catalogue of controllers: which controller a scenario names, loaded on demand (issue 25).

agent/controller.py is the interface (Observation, Command, the batch forms) and the registry a
controller module registers into (`register`); it discovers nothing. This module sits above it and
above every controller: it imports the built-in controllers (agent/controllers.py), and the flight
software of every mission room, `missions/<room>/fsw` (bus/discovery.py `import_role`: never a
room's `sense` or `report`), when a name is looked up that is not registered yet.
An agent image imports only its own controller's module (deploy/agent_image.py), so `make_controller`
loads the rest only when the name is missing.
"""
from __future__ import annotations

from typing import Any

import swarmhil.agent.controllers  # noqa: F401  (registers the built-in controllers: numpy only, scipy on use)
from swarmhil.agent.controller import Controller, OrbitInfo, registered_factory, registered_names, registered_validator
from swarmhil.bus.discovery import import_role


def load_controllers() -> None:
    """Import every mission room's flight software, missions/<room>/fsw (each registers its
    controllers by decorator when imported: adding a mission edits nothing here; the built-ins are
    imported above)."""
    import_role("fsw")


def validate_params(name: str, params: dict[str, Any]) -> None:
    """Check a controller's params with its registered validator (no-op when it has none)."""
    load_controllers()
    check = registered_validator(name)
    if check is not None:
        check(dict(params))


def _factory(name: str):  # type: ignore[no-untyped-def]
    f = registered_factory(name)
    if f is None:
        raise ValueError(f"unknown controller {name!r}; known: {registered_names()}")
    return f


def controller_module(name: str) -> str:
    """The module whose import registers controller `name` (an agent image imports only that one)."""
    load_controllers()
    return _factory(name).__module__


def make_controller(name: str, sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> Controller:
    """The controller `name` of spacecraft `sc_id` (its factory called with the scenario's params)."""
    if registered_factory(name) is None:  # an agent image has imported its controller's module only
        load_controllers()
    return _factory(name)(sc_id, orbit, params)


def known_controllers() -> list[str]:
    load_controllers()
    return registered_names()
