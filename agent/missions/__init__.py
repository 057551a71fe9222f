"""Flight software of one paper per room (`agent/missions/<room>/`).

Each room registers its controllers with `agent.controller.register` when its `controller`
module is imported; `load_all()` imports every room's `controller` so `make_controller` finds them.
"""
from __future__ import annotations

import importlib
import importlib.util
import pkgutil


def load_all() -> list[str]:
    """Import `agent.missions.<room>.controller` for every room that has one; return the rooms."""
    rooms = []
    for info in pkgutil.iter_modules(__path__):
        if not info.ispkg:
            continue
        name = f"{__name__}.{info.name}.controller"
        if importlib.util.find_spec(name) is not None:
            importlib.import_module(name)
            rooms.append(info.name)
    return rooms
