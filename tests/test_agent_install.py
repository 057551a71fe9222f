"""The agent-only install: the wheel of this checkout, installed without extras into a fresh venv,
runs a multi-process scenario with ideal sensing, its truth bit for bit that of the same run by the
project's own environment, and the viewer, the reports, the camera JIT and the campaign machinery
are not there.

The wheel is built from the sdist (tests/test_packaging.py `build_wheel`) and installed as a user
would, not editable: the run starts in a directory outside the checkout, and the test checks the
`swarmhil` it imports lives in the venv's site-packages, so a module or data file the wheel leaves
out fails the run or changes its truth. A 20-agent sabatini-20 run of 5 simulated minutes.
A system test: the install downloads the core wheels (about 130 MB, a few minutes);
the default suite keeps the import audit of every process role (tests/test_imports.py).
SWARMHIL_WHEELHOUSE=DIR adds `--find-links DIR` (e.g. `swarmhil image wheelhouse DIR`,
docs/containers.md) to install offline and faster. The memory bound is on each agent process's peak
RSS (resident set, shared pages counted in full: an upper bound of what it adds), as the import
audit measures it.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, topics

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
    from test_packaging import build_wheel

    wheel = build_wheel(tmp_path / "dist")
    subprocess.run([*pip, str(wheel), "-c", str(ROOT / "constraints.txt")], check=True, env=env, timeout=900)
    where = subprocess.run([py, "-c", "import swarmhil; print(swarmhil.__file__)"], capture_output=True, text=True,
                           env=env, cwd=tmp_path, check=True).stdout.strip()
    assert Path(where).is_relative_to(venv) and not Path(where).is_relative_to(ROOT), where  # the wheel, not the checkout

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
    ref = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "sabatini-20.toml"),
                          "--duration", "300", "--out", str(tmp_path / "ref"), "--run-id", s["run"], "--no-progress"],
                         capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert ref.returncode == 0, ref.stdout + ref.stderr
    truth = topics(out / "run.mcap", "truth")
    assert len(truth) == 31 and truth == topics(tmp_path / "ref" / "run.mcap", "truth")  # bit for bit the checkout's run
    agents = [json.loads(f.read_text()) for f in audit.glob("agent-*.json")]
    assert len(agents) == 20 and max(a["peak_rss_bytes"] for a in agents) <= 60e6  # peak RSS per agent

    r = subprocess.run([exe, "report", str(out)], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 1 and r.stderr.strip().count("\n") == 0 and "swarmhil[reports]" in r.stderr, r.stderr

