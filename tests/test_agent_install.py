"""The agent-only install (issue 18): `pip install swarmhil` without extras runs a multi-process
scenario with ideal sensing, and the viewer, the reports, the camera JIT and the campaign machinery
are not there.

A fresh venv in a temporary directory, the project installed into it (editable, no extras, at the
versions of constraints.txt), then a 20-agent sabatini-20 run of 5 simulated minutes with it.
A system test (issue 28; it was a study nobody ran): the install downloads the core wheels (about
130 MB) and took 2.5-4.5 min on the development machine; the default suite keeps the import audit
of every process role (tests/test_imports.py). SWARMHIL_WHEELHOUSE=DIR adds `--find-links DIR` (e.g.
`swarmhil image wheelhouse DIR`, docs/containers.md) to install offline and faster. The memory
bound is on each agent process's peak RSS (resident set, shared pages counted in full: an upper
bound of what it adds), as the import audit measures it.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS

EXTRAS_ONLY = ["rerun", "matplotlib", "numba", "PIL", "dask", "pyarrow", "jinja2", "plotly", "pandas"]


@pytest.mark.system
def test_agent_only_install_runs_a_multi_process_scenario(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    base = getattr(sys, "_base_executable", sys.executable)
    subprocess.run([base, "-m", "venv", str(venv)], check=True, env=env, timeout=120)
    py = str(venv / "bin" / "python")
    links = ["--find-links", os.environ["SWARMHIL_WHEELHOUSE"]] if os.environ.get("SWARMHIL_WHEELHOUSE") else []
    pip = [py, "-m", "pip", "install", "-q", *links]
    subprocess.run([*pip, "setuptools>=68", "wheel"], check=True, env=env, timeout=600)
    subprocess.run([*pip, "--no-build-isolation", "-e", str(ROOT), "-c", str(ROOT / "constraints.txt")],
                   check=True, env=env, timeout=900)

    probe = "import importlib.util, json; print(json.dumps({m: importlib.util.find_spec(m) is not None for m in %r}))"
    found = json.loads(subprocess.run([py, "-c", probe % EXTRAS_ONLY], capture_output=True, text=True, env=env,
                                      cwd=tmp_path, check=True).stdout)
    assert not any(found.values()), f"installed without being asked for: {[m for m, f in found.items() if f]}"

    exe, out, audit = str(venv / "bin" / "swarmhil"), tmp_path / "run", tmp_path / "audit"
    audit.mkdir()
    p = subprocess.run([exe, "run", str(SCENARIOS / "sabatini-20.toml"), "--duration", "300", "--out", str(out),
                        "--no-progress"], capture_output=True, text=True, cwd=tmp_path, timeout=600,
                       env={**env, "SWARMHIL_IMPORT_AUDIT": str(audit)})
    assert p.returncode == 0, p.stdout + p.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["steps"] == 30 and s["agents"] == 20 and not s["dead_agents"], s
    assert s["delta_v_total_mps"] > 0  # the controllers flew
    agents = [json.loads(f.read_text()) for f in audit.glob("agent-*.json")]
    assert len(agents) == 20 and max(a["peak_rss_bytes"] for a in agents) <= 60e6  # peak RSS per agent

    r = subprocess.run([exe, "report", str(out)], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 1 and r.stderr.strip().count("\n") == 0 and "swarmhil[reports]" in r.stderr, r.stderr
