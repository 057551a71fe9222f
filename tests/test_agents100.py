"""100 agent processes on one machine (issue 16): deploy/scenarios/sabatini-100.toml, a short
multi-process lockstep run over Zenoh. Every agent finishes every step (no dead agent, no missed
deadline), the truth holds 100 spacecraft at every step, every agent's PSS at exit (read by the import audit of
deploy/proc.py; its peak RSS, /proc VmHWM sampled during the run, printed beside it) is <= 60 MB, and no
process of the run is left afterwards. The 24 h figure is bench/bench_100.py (docs/benchmarks.md)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from conftest import ROOT, SCENARIOS, read_mcap
from test_imports import AGENT_RSS_MAX
from test_restart import _no_process_left

N, STEPS = 100, 40


def _vmhwm(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return 0


@pytest.mark.system
def test_100_agent_processes_in_lockstep(tmp_path: Path) -> None:
    audit, out = tmp_path / "audit", tmp_path / "run"
    audit.mkdir()
    env = dict(os.environ, SWARMHIL_IMPORT_AUDIT=str(audit))
    launcher = psutil.Popen([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "sabatini-100.toml"),
                             "--duration", str(STEPS * 10.0), "--out", str(out), "--no-progress"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    peak: dict[int, int] = {}  # agent pid -> largest VmHWM seen
    t_end = time.monotonic() + 170
    while launcher.poll() is None and time.monotonic() < t_end:
        for ch in launcher.children(recursive=True):
            try:
                if "agent" in ch.cmdline()[3:4]:  # python -m swarmhil.deploy.proc agent ...
                    peak[ch.pid] = max(peak.get(ch.pid, 0), _vmhwm(ch.pid))
            except (psutil.Error, OSError):
                pass
        time.sleep(0.2)
    if launcher.poll() is None:
        launcher.terminate()  # our own child, by PID; the launcher stops its processes
        launcher.wait(30)
    text = launcher.stdout.read().decode(errors="replace") if launcher.stdout else ""
    assert launcher.returncode == 0, text[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["agents"] == N and s["steps"] == STEPS, s
    assert s["dead_agents"] == {} and s["missed_deadlines"] == {} and s["late_commands"] == 0, s
    truth = [m for t, _l, _p, m in read_mcap(out / "run.mcap") if t == "truth"]
    assert [m.header.step for m in truth] == list(range(STEPS + 1))
    assert all(len(m.bodies) == N for m in truth)
    assert len(peak) == N, f"sampled {len(peak)} agent processes"
    # the bound on PSS, what 100 agents add up to (test_imports.AGENT_RSS_MAX says why not RSS); the
    # sampled and exact peak RSS are printed with it
    exact = [json.loads(f.read_text()) for f in audit.glob("agent-*.json")]
    pss = max(r["pss_bytes"] for r in exact)
    print(f"100 agents: max PSS {pss / 1e6:.1f} MB, max USS {max(r['uss_bytes'] for r in exact) / 1e6:.1f} MB, "
          f"sampled peak RSS {max(peak.values()) / 1e6:.1f} MB, exact {max(r['peak_rss_bytes'] for r in exact) / 1e6:.1f} MB")
    assert len(exact) == N and pss <= AGENT_RSS_MAX, f"max PSS {pss / 1e6:.1f} MB"
    _no_process_left(out)
