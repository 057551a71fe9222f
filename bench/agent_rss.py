"""Resident memory of a multi-process run's processes, per role (issue 16: <= 60 MB per agent).

    python bench/agent_rss.py [SCENARIO] [--duration 600] [--tree DIR ...] [--out DIR]

Runs `python -m swarmhil.deploy.cli run SCENARIO --duration D` from each source tree (default: this one) in
turn, samples the RSS of every child of the launcher with psutil every 0.5 s, and prints per tree
the median and maximum over the agent processes of each one's peak sampled RSS, and the plant's,
the recorder's and the launcher's. With a tree that has the import audit (deploy/proc.py
SWARMHIL_IMPORT_AUDIT) it also prints the median of the agents' exact peak (VmHWM) and the heavy
packages each role imported. The machine is
shared: memory, unlike time, hardly depends on the load, but the load is printed too.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

HEAVY = ("pydantic", "tqdm", "scipy", "click", "matplotlib", "rerun", "numba", "PIL", "dask", "pyarrow",
         "yaml", "jinja2", "plotly", "pandas", "mcap", "foxglove_schemas_protobuf", "psutil")


def role_of(cmdline: list[str]) -> str:
    if "swarmhil.deploy.proc" not in cmdline:
        return ""
    role = cmdline[cmdline.index("swarmhil.deploy.proc") + 1]
    if role == "agent" and "--id" in cmdline:
        return f"agent-{cmdline[cmdline.index('--id') + 1]}"
    if role == "companion" and "--name" in cmdline:
        return cmdline[cmdline.index("--name") + 1]
    return role


def measure(tree: Path, scenario: str, duration: float, out: Path, interval_s: float = 0.5,
            rescan_s: float = 5.0) -> dict:
    audit = out / "audit"
    audit.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, SWARMHIL_IMPORT_AUDIT=str(audit))
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(Path(scenario).resolve()), "--duration", str(duration),
           "--out", str(out / "run"), "--no-progress", "--overwrite"]
    launcher = psutil.Popen(cmd, cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    peak: dict[str, int] = {"launcher": 0}
    # The process tree is walked (all of /proc, and each child's command line) only every
    # `rescan_s`; in between only the known processes' RSS is read. (It walked the tree and read
    # 100 command lines every 0.1 s: CPU taken from the 100-agent run it measures. The sampled
    # peaks are a cross-check: each agent's exact VmHWM at exit comes from the import audit below.)
    roles: dict[int, tuple[psutil.Process, str]] = {}
    rescan = 0.0
    while launcher.poll() is None:
        try:
            peak["launcher"] = max(peak["launcher"], launcher.memory_info().rss)
            if time.monotonic() >= rescan:
                rescan = time.monotonic() + rescan_s
                for ch in launcher.children(recursive=True):
                    if ch.pid not in roles:
                        try:
                            roles[ch.pid] = (ch, role_of(ch.cmdline()))
                        except psutil.Error:
                            pass
            for pid, (ch, r) in list(roles.items()):
                if not r:
                    continue
                try:
                    peak[r] = max(peak.get(r, 0), ch.memory_info().rss)
                except psutil.Error:
                    del roles[pid]
        except psutil.Error:
            pass
        time.sleep(interval_s)
    text = launcher.stdout.read().decode(errors="replace")
    if launcher.returncode:
        raise SystemExit(f"run from {tree} failed ({launcher.returncode}):\n{text}")
    agents = sorted(v for k, v in peak.items() if k.startswith("agent-"))
    mods, hwm = {}, []
    for f in sorted(audit.glob("*.json")):
        d = json.loads(f.read_text())
        mods[d["role"]] = [m for m in d["modules"] if m in HEAVY]
        if d["role"].startswith("agent-"):
            hwm.append(d["peak_rss_bytes"])
    first_agent = min((r for r in mods if r.startswith("agent-")), default=None)
    return {"tree": str(tree), "agents": len(agents), "agent_median_mb": statistics.median(agents) / 1e6,
            "agent_max_mb": agents[-1] / 1e6, "plant_mb": peak.get("plant", 0) / 1e6,
            "recorder_mb": peak.get("recorder", 0) / 1e6, "launcher_mb": peak["launcher"] / 1e6,
            "agent_vmhwm_median_mb": statistics.median(hwm) / 1e6 if hwm else None,
            "heavy_imports": {k: v for k, v in mods.items() if not k.startswith("agent-") or k == first_agent}}


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", nargs="?", default=str(root / "deploy/scenarios/sabatini-20.toml"))
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--tree", type=Path, action="append", help="source tree to run from (repeatable; default this one)")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    out = a.out or Path(tempfile.mkdtemp(prefix="agent-rss-"))
    print(f"load average {' '.join(Path('/proc/loadavg').read_text().split()[:3])}", flush=True)
    for i, tree in enumerate(a.tree or [root]):
        r = measure(tree.resolve(), a.scenario, a.duration, out / f"t{i}")
        print(json.dumps(r), flush=True)
        print(f"{tree}: {r['agents']} agents, median peak RSS {r['agent_median_mb']:.1f} MB "
              f"(max {r['agent_max_mb']:.1f}); plant {r['plant_mb']:.1f}, recorder {r['recorder_mb']:.1f}, "
              f"launcher {r['launcher_mb']:.1f} MB", flush=True)
    print(f"load average {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")


if __name__ == "__main__":
    main()
