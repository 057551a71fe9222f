"""Optional packages (the extras of pyproject.toml), imported where they are used.

An agent image installs only the core (`pip install swarmhil`: Zenoh, numpy, scipy, protobuf, MCAP,
pydantic, click); the viewer, the reports, the camera's JIT and the campaigns are extras
(docs/packaging.md). `require(module, what)` imports an optional module at its place of use, and
when its package is missing raises `MissingExtra` with one line naming the extra to install; the
command line prints that line (exit code 1).
"""
from __future__ import annotations

import importlib
from types import ModuleType

# top-level package -> the extra that installs it
EXTRAS = {
    "rerun": "viewer", "rerun_cli": "viewer", "foxglove": "viewer",
    "matplotlib": "reports", "jinja2": "reports", "plotly": "reports", "pandas": "reports",
    "numba": "camera", "PIL": "camera",
    "dask": "campaign", "distributed": "campaign", "pyarrow": "campaign",
}


class MissingExtra(ImportError):
    """An optional package is not installed; the message is one line naming the extra."""


def require(module: str, what: str) -> ModuleType:
    """`importlib.import_module(module)`, or MissingExtra("<what>: the package ... is not installed
    (pip install 'swarmhil[<extra>]' ...)") when the module's own package is missing (a missing
    dependency of that package, or a broken install, raises as usual)."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        top = module.split(".")[0]
        if exc.name is None or exc.name.split(".")[0] != top:
            raise
        extra = EXTRAS.get(top, "all")
        raise MissingExtra(f"{what}: the package {top!r} is not installed (pip install 'swarmhil[{extra}]', "
                           f"or swarmhil[all])") from None
