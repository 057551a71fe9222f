"""Mission rooms: one subpackage per paper, each registering its own controller(s).

`load_missions()` imports every subpackage so their `agent.controller.register` decorators run;
`agent/controllers.py` calls it, so a new paper is a new room and no central file is edited.
"""
from __future__ import annotations

import importlib
import pkgutil


def load_missions() -> list[str]:
    """Import every mission subpackage (registering its controllers); return their names."""
    names = [m.name for m in pkgutil.iter_modules(__path__) if m.ispkg]
    for name in names:
        importlib.import_module(f"{__name__}.{name}")
    return names
