"""The mission rooms' closed-loop checks (tests/missions/*.py) as sources: their `simulate` /
`run_closed_loop` and `summary` functions are the code that made the docs' tables, so the claims
call them rather than copy them. They live in the repository's tests, so these sources run from a
checkout (as the system tests do), not from an installed wheel."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent


def mission_test_module(name: str) -> ModuleType:
    """tests/missions/NAME.py, imported once (its directory on sys.path, as pytest puts it)."""
    return test_module(f"missions/{name}")


def test_module(name: str) -> ModuleType:
    """tests/NAME.py (NAME may hold a directory), imported once, its directory and tests/ on sys.path."""
    key = f"claims_src_{name.replace('/', '_')}"
    if key in sys.modules:
        return sys.modules[key]
    path = ROOT / "tests" / f"{name}.py"
    for d in (str(ROOT), str(path.parent), str(ROOT / "tests")):
        if d not in sys.path:
            sys.path.insert(0, d)
    spec = importlib.util.spec_from_file_location(key, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"{path}: cannot be imported")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[key] = mod
    spec.loader.exec_module(mod)
    return mod
