"""Soak benchmark (issue 17): a real-time run at a high speed-up, deadline misses and memory per process.

    .venv/bin/python bench/soak.py                                   # drift-20, 24 h at x500 (~3 min wall)
    .venv/bin/python bench/soak.py --speed 100                       # the periodic x100 check (~15 min)
    .venv/bin/python bench/soak.py --scenario deploy/scenarios/sabatini-20-camera-filter.toml --speed 100

Runs `swarmhil run SCENARIO --mode realtime --speed S` as its own process, reads the children's
PIDs from DIR/run.json and samples every process's resident memory (/proc/PID/status VmRSS) every
`--sample` seconds. Reports the plant's missed deadlines and late commands (summary.json), and
per process: RSS at the start of the second quarter of the run (after warm-up) and at the end, and
the least-squares slope over the second half (MiB per simulated hour; flat is |slope| well under
1 % of the RSS per hour). The load average before and after is printed: under the shared machine's
load a miss may be the machine's, not the system's.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def rss_mib(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def memory_table(samples: dict[str, list[tuple[float, float]]], speed: float,
                 window: tuple[float, float]) -> dict[str, dict[str, float]]:
    """Per process, over the plant's stepping loop only (window, wall seconds; start-up and
    shutdown left out): RSS after warm-up (second quarter), at the end, and the slope over the
    second half (MiB per simulated hour)."""
    out = {}
    for name, all_pts in samples.items():
        pts = [p for p in all_pts if window[0] <= p[0] <= window[1]]
        if len(pts) < 8:
            continue
        t = np.array([p[0] for p in pts])
        m = np.array([p[1] for p in pts])
        q1, half = t[0] + 0.25 * (t[-1] - t[0]), t[0] + 0.5 * (t[-1] - t[0])
        sel = t >= half
        slope_per_wall_s = float(np.polyfit(t[sel], m[sel], 1)[0]) if sel.sum() >= 3 else float("nan")
        out[name] = {"rss_warm_mib": float(np.median(m[(t >= q1) & (t < half)])) if ((t >= q1) & (t < half)).any() else float("nan"),
                     "rss_end_mib": float(np.median(m[-max(3, len(m) // 20):])),
                     "rss_max_mib": float(m.max()),
                     "slope_mib_per_sim_h": slope_per_wall_s * 3600.0 / speed}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default=str(ROOT / "deploy/scenarios/drift-20.toml"))
    ap.add_argument("--duration", type=float, default=86400.0, help="simulated seconds")
    ap.add_argument("--speed", type=float, default=500.0)
    ap.add_argument("--sample", type=float, default=1.0, help="seconds between memory samples")
    ap.add_argument("--out", help="run directory (default a fresh temporary one)")
    a = ap.parse_args()
    out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="swarmhil-soak-")) / "run"
    load0 = os.getloadavg()
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", a.scenario, "--mode", "realtime", "--speed", str(a.speed),
           "--duration", str(a.duration), "--out", str(out), "--no-progress", "--overwrite"]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    samples: dict[str, list[tuple[float, float]]] = {}
    pids: dict[str, int] = {}
    plant_gone = None
    while proc.poll() is None:
        if not pids and (out / "run.json").exists():
            try:
                pids = {**json.loads((out / "run.json").read_text())["pids"], "launcher": proc.pid}
            except (ValueError, KeyError):
                pids = {}
        now = time.monotonic() - t0
        for name, pid in pids.items():
            r = rss_mib(pid)
            if r is not None:
                samples.setdefault(name, []).append((now, r))
            elif name == "plant" and plant_gone is None:
                plant_gone = now
        time.sleep(a.sample)
    log = proc.stdout.read() if proc.stdout else ""
    wall = time.monotonic() - t0
    load1 = os.getloadavg()
    s = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    # the plant's loop: the last loop_wall_s seconds before the plant exited
    loop = float(s.get("loop_wall_s") or a.duration / a.speed)
    end = plant_gone if plant_gone is not None else wall
    mem = memory_table(samples, a.speed, (end - loop, end)) if s.get("steps") else {}  # no loop, no figures
    missed = s.get("missed_deadlines", {})
    report = {"scenario": Path(a.scenario).name, "speed": a.speed, "duration_s": a.duration, "exit_code": proc.returncode,
              "steps": s.get("steps"), "wall_s": wall, "loop_wall_s": loop, "missed_deadlines_total": int(sum(missed.values())),
              "missed_deadlines": missed, "late_commands": s.get("late_commands"), "dead_agents": s.get("dead_agents"),
              "load_before": load0, "load_after": load1, "memory": mem, "run_dir": str(out)}
    print(f"{report['scenario']}: {a.duration / 3600:.1f} h simulated at x{a.speed:g}: loop {loop:.0f} s wall (run {wall:.0f} s), exit {proc.returncode}, "
          f"{report['steps']} steps; missed deadlines {report['missed_deadlines_total']}, late commands "
          f"{report['late_commands']}, dead {sorted(report['dead_agents'] or {})}; load {load0[0]:.1f} -> {load1[0]:.1f}")
    kinds = {"agents": [k for k in mem if k.startswith("agent-")], **{k: [k] for k in mem if not k.startswith("agent-")}}
    print(f"{'process':12s} {'n':>3s} {'RSS warm MiB':>13s} {'RSS end MiB':>12s} {'max MiB':>8s} {'slope MiB/sim h (worst)':>24s}")
    for kind, names in kinds.items():
        if not names:
            continue
        rows = [mem[n] for n in names]
        worst = max(rows, key=lambda r: abs(r["slope_mib_per_sim_h"]))
        print(f"{kind:12s} {len(rows):3d} {np.median([r['rss_warm_mib'] for r in rows]):13.1f} "
              f"{np.median([r['rss_end_mib'] for r in rows]):12.1f} {max(r['rss_max_mib'] for r in rows):8.1f} "
              f"{worst['slope_mib_per_sim_h']:24.3f}")
    if proc.returncode:
        print(f"the run failed (exit {proc.returncode}): {str(s.get('failure', ''))[:500] or log[-2000:]}")
    print(json.dumps(report))


if __name__ == "__main__":
    main()
