"""Discovery of plug-in modules: the one helper every registry uses (issue 25).

A registry (controllers, sensing kinds, report sections) fills itself when the modules that
register into it are imported; `import_all(package)` imports every module of a package by name, so
adding a plug-in is adding a module and no central file is edited. Standard library only: the
plant, the agent and the reporter each call it for their own package, and importing this module
loads nothing of the project.
"""
from __future__ import annotations

import importlib
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
