"""Discovery of plug-in modules: the one helper every registry uses (issue 25).

A registry (controllers, sensing kinds, report sections) fills itself when the modules that
register into it are imported; `import_all(package)` imports every module of a package by name, so
adding a plug-in is adding a module and no central file is edited. `import_role(role)` imports
one part of every mission room under `missions/` (`fsw`, `sense` or `report`: each process loads its
own part, never the whole room). Standard library only: the plant, the agent and the reporter each
call it for their own package, and importing this module loads nothing of the project.
"""
from __future__ import annotations

import importlib
import importlib.util
import pkgutil


def import_all(package: str, *, packages_only: bool = False, skip: tuple[str, ...] = ()) -> list[str]:
    """Import every module directly under `package` (with `packages_only`, its subpackages only),
    except those named in `skip`, in name order; return their short names."""
    pkg = importlib.import_module(package)
    names = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__)
                   if (m.ispkg or not packages_only) and m.name not in skip)
    for name in names:
        importlib.import_module(f"{package}.{name}")
    return names


ROOMS = "swarmhil.missions"
"""The package of the mission rooms (docs/architecture.md "Mission rooms (issue 25)")."""


ROLES = ("contract", "fsw", "sense", "report")
"""The parts of a room, by the process that imports each (contract: every process)."""

_OUTSIDE: list[str] = []
"""Rooms outside the source tree, by package name, in the order added ([run].rooms; add_rooms)."""


class RoomError(ValueError):
    """A room named by a scenario that is not an importable room package."""


def check_room(name: str) -> None:
    """`name` is an importable package (found without importing it: a room's `__init__` imports
    nothing) with at least one of a room's parts; else RoomError saying what is missing."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError) as exc:
        raise RoomError(f"room {name!r} does not import ({type(exc).__name__}: {exc})") from None
    if spec is None:
        raise RoomError(f"room {name!r} is not importable (not on sys.path / PYTHONPATH)")
    if spec.submodule_search_locations is None:
        raise RoomError(f"room {name!r} is a module, not a package with {'/'.join(ROLES)} parts")
    if not any(importlib.util.find_spec(f"{name}.{role}") is not None for role in ROLES):
        raise RoomError(f"room {name!r} has none of the parts {', '.join(ROLES)}")


def add_rooms(names: list[str] | tuple[str, ...]) -> None:
    """Rooms from outside the source tree (a scenario's [run].rooms): `import_role` imports their
    parts after the source tree's rooms. Each is checked (check_room) and none is imported here."""
    for name in names:
        check_room(name)
        if name not in _OUTSIDE:
            _OUTSIDE.append(name)


def import_role(role: str, package: str = ROOMS) -> list[str]:
    """Import one part of every mission room: `{package}.<room>.{role}` (`fsw` in an agent,
    `sense` in the plant, `report` in the reporter), for the rooms that have it, in name order, then
    the same part of every room added from outside the tree (add_rooms); return the rooms' names.
    Never the whole room: a room's `__init__` imports nothing, so loading
    `missions.p003_surround.sense` loads neither its `fsw` nor its `report`."""
    rooms = importlib.import_module(package)
    names = []
    for m in sorted(pkgutil.iter_modules(rooms.__path__), key=lambda m: m.name):
        if m.ispkg and importlib.util.find_spec(f"{package}.{m.name}.{role}") is not None:
            importlib.import_module(f"{package}.{m.name}.{role}")
            names.append(m.name)
    for name in _OUTSIDE if package == ROOMS else ():
        if importlib.util.find_spec(f"{name}.{role}") is not None:
            importlib.import_module(f"{name}.{role}")
            names.append(name)
    return names


def room_parts_loaded(modules: list[str] | tuple[str, ...] | set[str]) -> list[str]:
    """"<room>.<part>" of every room part among loaded module names, for the import audit of each
    process (deploy/proc.py): the source tree's rooms (`swarmhil.missions.<room>.<part>`) and, from
    outside the tree, every top-level package with a loaded `<package>.<part>` (an agent knows no
    [run].rooms: it imports its controller's module by name)."""
    found = set()
    for m in modules:
        parts = m.split(".")
        if m.startswith(ROOMS + ".") and len(parts) > 3 and parts[3] in ROLES:
            found.add(f"{parts[2]}.{parts[3]}")
        elif len(parts) == 2 and parts[1] in ROLES and parts[0] != "swarmhil":
            found.add(f"{parts[0]}.{parts[1]}")
    return sorted(found)
