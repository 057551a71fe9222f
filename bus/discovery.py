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


ROOMS = "missions"
"""The package of the mission rooms (docs/architecture.md "Mission rooms (issue 25)")."""


def import_role(role: str, package: str = ROOMS) -> list[str]:
    """Import one part of every mission room: `{package}.<room>.{role}` (`fsw` in an agent,
    `sense` in the plant, `report` in the reporter), for the rooms that have it, in name order;
    return the rooms' names. Never the whole room: a room's `__init__` imports nothing, so loading
    `missions.p003_surround.sense` loads neither its `fsw` nor its `report`."""
    rooms = importlib.import_module(package)
    names = []
    for m in sorted(pkgutil.iter_modules(rooms.__path__), key=lambda m: m.name):
        if m.ispkg and importlib.util.find_spec(f"{package}.{m.name}.{role}") is not None:
            importlib.import_module(f"{package}.{m.name}.{role}")
            names.append(m.name)
    return names
