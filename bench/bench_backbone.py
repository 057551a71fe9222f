"""Backbone benchmark (issue 2): the 24 h drift-20 run in lockstep, the bus floor with the same
number of processes and steps, and the in-process run, all in one invocation; ratios printed.

    make bench            # or: .venv/bin/python bench/bench_backbone.py [--duration 86400]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default=str(ROOT / "deploy/scenarios/drift-20.toml"))
    ap.add_argument("--duration", type=float, default=86400.0)
    a = ap.parse_args()
    from deploy.launcher import MultiProcessRun, run_in_process
    from deploy.scenario import load_scenario

    sc = load_scenario(a.scenario).with_overrides(duration_s=a.duration)
    steps, n = sc.steps, len(sc.ids)
    out = Path(tempfile.mkdtemp(prefix="swarmhil-bench-"))
    rows = {}
    t0 = time.perf_counter()
    res = MultiProcessRun(a.scenario, sc, out / "mp", "bench-mp", progress=False,
                          overrides={"duration": a.duration}).execute()
    rows["multi-process lockstep (launcher wall, incl. start-up)"] = time.perf_counter() - t0
    rows["multi-process lockstep (plant loop)"] = res.summary.get("loop_wall_s", float("nan"))
    t0 = time.perf_counter()
    run_in_process(sc, out / "ip", "bench-ip")
    rows["in-process"] = time.perf_counter() - t0
    fl = subprocess.run([sys.executable, str(ROOT / "bench/bus_floor.py"), "--workers", str(n), "--steps", str(steps)],
                        capture_output=True, text=True, check=True)
    floor = float(fl.stdout.split(",")[2].split()[0])
    rows["bus floor (empty tick/reply, same processes and steps)"] = floor
    print(f"\n{sc.name}: {n} agents, {steps} steps of {sc.step_s} s ({a.duration / 3600:.1f} h simulated)")
    print(f"{'what':58s} {'wall s':>9s} {'ms/step':>9s} {'x floor':>8s}")
    for k, v in rows.items():
        print(f"{k:58s} {v:9.2f} {v / steps * 1e3:9.3f} {v / floor:8.2f}")
    print(json.dumps({"rows": rows, "steps": steps, "agents": n}))


if __name__ == "__main__":
    main()
