"""The wheel installs one top-level name, `swarmhil` (issue 25): `pip install swarmhil` into a user's
shared environment puts no generic `agent`, `bus`, `link`, `plant`, `deploy` or `dashboards` package
into site-packages. Builds the sdist of this checkout and the wheel from it with setuptools' PEP 517 backend (about 6 s)
and reads it with zipfile; tests/test_wheel_install.py (system) installs and runs one.
"""
from __future__ import annotations

import configparser
import os
import subprocess
import sys
import zipfile
from pathlib import Path

from conftest import ROOT

from swarmhil.deploy.image import sdist_tree

GENERIC = {"agent", "bus", "link", "plant", "deploy", "dashboards", "missions", "claims"}


def build_wheel(dist: Path) -> Path:
    """The wheel built from the sdist (as `python -m build` and `swarmhil image wheelhouse` do): a
    checkout's `build/` folder may hold modules since moved or deleted, which a wheel built in the
    tree would carry."""
    src = sdist_tree(dist)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    code = "import sys; from setuptools import build_meta as b; print(b.build_wheel(sys.argv[1]))"
    r = subprocess.run([sys.executable, "-c", code, str(dist)], cwd=src, env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    return dist / r.stdout.split()[-1]


def test_the_wheel_installs_only_the_swarmhil_name(tmp_path: Path) -> None:
    with zipfile.ZipFile(build_wheel(tmp_path)) as whl:
        names = whl.namelist()
        info = next(n.split("/")[0] for n in names if n.endswith(".dist-info/METADATA"))
        tops = {n.split("/")[0] for n in names} - {info}
        assert tops == {"swarmhil"}, sorted(tops)
        top_level = whl.read(f"{info}/top_level.txt").decode().split()
        entry = configparser.ConfigParser()
        entry.read_string(whl.read(f"{info}/entry_points.txt").decode())
    assert top_level == ["swarmhil"], top_level
    assert entry["console_scripts"]["swarmhil"] == "swarmhil.deploy.cli:main"
    # each folder of the design card is in it, through the namespace, with its data files
    for must in ("swarmhil/agent/node.py", "swarmhil/plant/node.py", "swarmhil/bus/swarmhil.proto",
                 "swarmhil/bus/keys.json", "swarmhil/link/node.py", "swarmhil/deploy/scenarios/demo.toml",
                 "swarmhil/dashboards/templates/", "swarmhil/missions/p000_capture/contract.py",
                 "swarmhil/claims/recorded.json"):
        assert any(n.startswith(must) for n in names), must
    # as files, each once: no second copy under a generic name
    assert not GENERIC & {n.split("/")[0] for n in names}
    assert len(names) == len(set(names))
    # and only the checkout's modules: none that was moved or deleted
    stray = [n for n in names if n.endswith(".py") and not (ROOT / n).is_file()]
    assert not stray, stray
