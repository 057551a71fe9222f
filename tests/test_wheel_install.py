"""The package installs from its wheel (issue 28): sdist, then the wheel built from that sdist, installed
(not editable) with every extra into a fresh venv, runs a short scenario and writes its report from a
folder outside the repository.

What must be in the package for that: the scenario files (deploy/scenarios), the protobuf contract
and key map (bus/swarmhil.proto, bus/keys.json), the report templates and the plotly bundle. The
scenario is the installed package's own file, found through the venv's Python. System test: the
install of `[all]` at constraints.txt takes minutes (the index or pip's find-links).
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from conftest import ROOT

pytestmark = pytest.mark.system


def _ok(argv: list[str], **kw: object) -> str:
    r = subprocess.run(argv, capture_output=True, text=True, **kw)  # type: ignore[call-overload]
    assert r.returncode == 0, f"{' '.join(map(str, argv))}: {r.stdout[-2000:]}{r.stderr[-3000:]}"
    return r.stdout


def test_wheel_installs_and_runs_outside_the_repository(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    dist = tmp_path / "dist"
    backend = "import sys; from setuptools import build_meta as b; print(getattr(b, sys.argv[1])(sys.argv[2]))"
    sdist = dist / _ok([sys.executable, "-c", backend, "build_sdist", str(dist)], cwd=ROOT, env=env).split()[-1]
    with tarfile.open(sdist) as tf:
        tf.extractall(tmp_path / "src", filter="data")
    src = next((tmp_path / "src").iterdir())  # the wheel from the sdist alone, as `python -m build` does
    wheel = dist / _ok([sys.executable, "-c", backend, "build_wheel", str(dist)], cwd=src, env=env).split()[-1]

    venv = tmp_path / "venv"
    _ok([getattr(sys, "_base_executable", sys.executable), "-m", "venv", str(venv)], env=env, timeout=120)
    py, exe = str(venv / "bin" / "python"), str(venv / "bin" / "swarmhil")
    _ok([py, "-m", "pip", "install", "-q", f"{wheel}[all]", "-c", str(ROOT / "constraints.txt")], env=env, timeout=1500)

    away = tmp_path / "elsewhere"  # no checkout here or above: the installed package only
    away.mkdir()
    where = json.loads(_ok([py, "-c", "import json, pathlib; from swarmhil import bus, deploy; print(json.dumps([str(pathlib.Path("
                                      "m.__file__).parent) for m in (bus, deploy)]))"], cwd=away, env=env))
    assert all(str(venv) in w for w in where), where  # not the repository's sources
    scenario = Path(where[1]) / "scenarios" / "demo.toml"
    assert (Path(where[0]) / "swarmhil.proto").is_file() and (Path(where[0]) / "keys.json").is_file()
    _ok([exe, "run", str(scenario), "--in-process", "--duration", "120", "--out", "run", "--no-progress"], cwd=away,
        env=env, timeout=600)
    s = json.loads((away / "run" / "summary.json").read_text())
    assert s["steps"] > 0 and not s["dead_agents"], s
    _ok([exe, "report", "run"], cwd=away, env=env, timeout=600)
    page = away / "run" / "report" / "index.html"
    html = page.read_text()
    local = re.findall(r'src="([^":]+)"', html)  # scripts and images the page loads from its own folder
    assert "<html" in html.lower() and all((page.parent / s).is_file() for s in local), local
