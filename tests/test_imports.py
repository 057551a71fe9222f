"""What each process of a run imports (issues 16, 18): an agent image holds flight software, not the
scenario validation, the launcher, the viewer, the reports or the campaign machinery.

A real multi-process run (router, plant, link channel, recorder, 4 agents with the behavioural
controller and ideal sensing, beacons over the link) with SWARMHIL_IMPORT_AUDIT set: each child
writes the top-level packages it has imported and its peak RSS when it stops (deploy/proc.py), and
the test checks them role by role. The DRE cache starts empty: the launcher fills it before the
agents start (deploy/agent_image.agent_configs), so no agent solves it with scipy.
"""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

from conftest import ROOT, SCENARIOS

OPTIONAL = {"matplotlib", "rerun", "numba", "PIL", "dask", "distributed", "pyarrow", "jinja2", "plotly", "pandas",
            "foxglove"}  # the extras (bus/optional.py): no process of a run without them needs them
NOT_IN_AGENT = OPTIONAL | {"pydantic", "scipy", "tqdm", "click", "yaml", "psutil", "mcap", "mcap_protobuf",
                           "foxglove_schemas_protobuf"}
# issue 16: <= 60 MB per agent process. Asserted on PSS (what N agents add up to): RSS also counts
# every mapped page of the shared numpy/zenoh libraries in full, and how many pages the kernel maps
# depends on the page cache, not on this code: the same imports measured RssFile 15.5 MB in a venv
# installed days ago and 22.6 MB in a venv just installed (a fresh CI checkout), RssAnon 17.9 MB in
# both (docs/performance.md "RSS, PSS and USS"). The peak RSS is reported in the messages.
AGENT_RSS_MAX = 60e6


def test_each_process_role_imports_only_what_it_needs(tmp_path: Path) -> None:
    audit, out = tmp_path / "audit", tmp_path / "run"
    audit.mkdir()
    env = dict(os.environ, SWARMHIL_IMPORT_AUDIT=str(audit), SWARMHIL_CACHE_DIR=str(tmp_path / "cache"))
    p = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "sabatini-20-beacon.toml"),
                        "--duration", "60", "--out", str(out), "--no-progress", "--set", "dispersion.count=4"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=240)
    assert p.returncode == 0, p.stdout + p.stderr
    roles = {f.stem: json.loads(f.read_text()) for f in audit.glob("*.json")}
    assert set(roles) == {"plant", "recorder", "channel", "agent-sc01", "agent-sc02", "agent-sc03", "agent-sc04"}, roles
    for name, r in roles.items():
        mods = set(r["modules"])
        assert "zenoh" in mods and "numpy" in mods, name  # the audit sees real imports
        assert not mods & OPTIONAL, f"{name} imported optional packages {sorted(mods & OPTIONAL)}"
        if name.startswith("agent-"):
            assert not mods & NOT_IN_AGENT, f"{name} imported {sorted(mods & NOT_IN_AGENT)}"
            assert r["pss_bytes"] <= AGENT_RSS_MAX, (f"{name}: PSS {r['pss_bytes'] / 1e6:.1f} MB (USS "
                                                     f"{r['uss_bytes'] / 1e6:.1f}, peak RSS {r['peak_rss_bytes'] / 1e6:.1f})")
            assert r["uss_bytes"] < r["pss_bytes"] <= r["rss_bytes"], name  # the three measures are consistent
            assert json.loads((out / "agents" / f"{name[6:]}.json").read_text())["steps"] == 6
    assert "mcap" in roles["recorder"]["modules"] and "tqdm" not in roles["recorder"]["modules"]
    assert any((tmp_path / "cache").glob("dre-*.npz"))  # filled by the launcher, read by the agents


PROJECT = {"agent", "plant", "bus", "link", "deploy", "dashboards", "missions", "tests", "conftest"}


def test_no_private_imports_from_dependencies() -> None:
    """Product code imports only public modules of its dependencies (no `scipy.integrate._ivp`)."""
    bad = []
    for path in ROOT.glob("*/**/*.py"):
        top = path.relative_to(ROOT).parts[0]
        if top not in PROJECT - {"tests"}:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module] if isinstance(node, ast.ImportFrom) and node.module and not node.level else []
            for n in names:
                parts = n.split(".")
                if parts[0] not in PROJECT and any(x.startswith("_") and x != "__future__" for x in parts[1:]):
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {n}")
    assert not bad, bad
