"""The real-time-factor curve (issue 29): how fast the multi-process stack flies N agents, against
the bus contract's own floor, on this machine.

    python bench/rtf_curve.py                                 # paper 002 N = 1..200, paper 000 N = 5, 10, 20
    python bench/rtf_curve.py --agents 1,5,10 --p000 '' --steps 30 --json rtf.json

For each point, in one invocation:

- **lockstep**: `swarmhil run SCENARIO` (one OS process per agent, Zenoh on loopback, every message
  recorded); the real-time factor is simulated seconds / the plant loop's wall seconds
  (summary.json `loop_wall_s`, start-up excluded);
- **real time**: the largest speed-up without a missed deadline or a late command, searched
  downwards from 0.8 x the lockstep factor (x0.7 per try, at most `--tries` runs): `swarmhil run
  --mode realtime --speed S`;
- **contract floor**: `bench/bus_floor.py --contract` with N workers and the same steps: the
  run's own messages per step with no physics, flight software, decoding or recording.

Paper 002: deploy/scenarios/sabatini-100.toml with `dispersion.count = N` (ideal relative sensing,
10 s steps). Paper 000: the first N spacecraft of deploy/scenarios/capture-20.toml (20 Hz). The
floor's message sizes are drift-20's (bench/bus_floor.py SIZES) for both: for paper 000 the floor
understates its larger stimuli. The machine is shared: compare each point's ratio to its own floor,
not absolute figures across invocations. The last line printed is the result as JSON.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

from bench_backbone import load  # noqa: E402

P002 = ROOT / "deploy/scenarios/sabatini-100.toml"
P000 = ROOT / "deploy/scenarios/capture-20.toml"


def first_spacecraft(text: str, n: int) -> str:
    """A scenario TOML cut after its first n `[[spacecraft]]` tables (they are the file's last tables)."""
    starts = [m.start() for m in re.finditer(r"(?m)^\[\[spacecraft\]\]$", text)]
    if len(starts) < n:
        raise ValueError(f"the scenario has {len(starts)} spacecraft, fewer than {n}")
    return text if n == len(starts) else text[:starts[n]]


def swarmhil_run(path: Path, out: Path, sets: list[str], *extra: str) -> dict[str, Any]:
    """One `swarmhil run` as its own process; its summary.json."""
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(path), "--out", str(out), "--no-progress",
           *[a for s in sets for a in ("--set", s)], *extra]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=7200)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {p.returncode}\n{p.stdout[-1500:]}{p.stderr[-1500:]}")
    return json.loads((out / "summary.json").read_text())


def contract_floor_s(n: int, steps: int) -> float:
    """Wall seconds of `bench/bus_floor.py --contract` with n workers and `steps` steps (from its
    ms/step, which it prints to three decimals)."""
    fl = subprocess.run([sys.executable, str(ROOT / "bench/bus_floor.py"), "--workers", str(n), "--steps", str(steps),
                         "--contract"], capture_output=True, text=True, check=True, timeout=7200)
    ms = re.search(r"([0-9.]+) ms/step", fl.stdout)
    if ms is None:
        raise RuntimeError(f"bus_floor.py printed no ms/step: {fl.stdout[-500:]}")
    return float(ms.group(1)) * steps / 1e3


def misses(summary: dict[str, Any]) -> int:
    """Deadlines missed by any agent plus commands that came late (summary.json)."""
    return int(sum((summary.get("missed_deadlines") or {}).values())) + int(summary.get("late_commands") or 0)


def point(path: Path, sets: list[str], n: int, steps: int, step_s: float, tries: int, work: Path) -> dict[str, Any]:
    """Lockstep factor, real-time speed without misses, and the contract floor for one scenario."""
    sim_s = steps * step_s
    sets = [*sets, f"run.duration_s={sim_s}"]
    lock = swarmhil_run(path, work / "lock", sets)
    loop_s = float(lock["loop_wall_s"])
    rtf_lock = sim_s / loop_s
    speed = float(f"{0.8 * rtf_lock:.2g}")
    tried: list[dict[str, Any]] = []
    rt_ok = None
    for i in range(tries):
        s = swarmhil_run(path, work / f"rt{i}", sets, "--mode", "realtime", "--speed", f"{speed:g}")
        tried.append({"speed": speed, "misses": misses(s)})
        if misses(s) == 0:
            rt_ok = speed
            break
        speed = float(f"{0.7 * speed:.2g}")
    floor_s = contract_floor_s(n, steps)
    return {"agents": n, "steps": steps, "step_s": step_s, "sim_s": sim_s, "lockstep_loop_s": loop_s,
            "rtf_lockstep": rtf_lock, "realtime_speed_no_miss": rt_ok, "realtime_tries": tried,
            "floor_s": floor_s, "rtf_floor": sim_s / floor_s, "lockstep_over_floor": loop_s / floor_s}


def measure(agents: list[int], steps: int, p000: list[int], p000_steps: int, tries: int) -> dict[str, Any]:
    """Every point of the curve in one invocation (see the module docstring)."""
    result: dict[str, Any] = {"load_start": load(), "p002": [], "p000": []}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rtf-") as d:
        for n in agents:
            work = Path(d) / f"p002-{n}"
            work.mkdir()
            r = point(P002, [f"dispersion.count={n}", "dispersion.require_weakly_connected=false",
                             f'run.name="rtf-{n}"'], n, steps, 10.0, tries, work)
            result["p002"].append(r)
            print(json.dumps({"paper": "002", **r}), file=sys.stderr, flush=True)
        for n in p000:
            work = Path(d) / f"p000-{n}"
            work.mkdir()
            path = work / f"capture-{n}.toml"
            path.write_text(first_spacecraft(P000.read_text(), n))
            r = point(path, [], n, p000_steps, 0.05, tries, work)
            result["p000"].append(r)
            print(json.dumps({"paper": "000", **r}), file=sys.stderr, flush=True)
    result["load_end"] = load()
    result["wall_s"] = time.perf_counter() - t0
    return result


def figure(result: dict[str, Any], path: Path) -> None:
    """Real-time factor against N: lockstep, real time without misses, and the contract floor."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, title in ((axes[0], "p002", "paper 002, ideal sensing, 10 s steps"),
                           (axes[1], "p000", "paper 000, 20 Hz")):
        pts = result[key]
        if not pts:
            ax.set_visible(False)
            continue
        n = [p["agents"] for p in pts]
        ax.plot(n, [p["rtf_floor"] for p in pts], "k:", marker=".", label="contract floor (bus only)")
        ax.plot(n, [p["rtf_lockstep"] for p in pts], "C0-", marker="o", label="lockstep")
        rt = [(p["agents"], p["realtime_speed_no_miss"]) for p in pts if p["realtime_speed_no_miss"]]
        if rt:
            ax.plot(*zip(*rt), "C1--", marker="s", label="real time, no missed deadline")
        ax.axhline(1.0, color="0.6", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("agents (one OS process each)")
        ax.set_ylabel("real-time factor (simulated s / wall s)")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", default="1,5,10,20,50,100,200", help="paper 002 swarm sizes")
    ap.add_argument("--steps", type=int, default=60, help="paper 002 steps per run (10 s each)")
    ap.add_argument("--p000", default="5,10,20", help="paper 000 swarm sizes ('' for none)")
    ap.add_argument("--p000-steps", type=int, default=200, help="paper 000 steps per run (0.05 s each)")
    ap.add_argument("--tries", type=int, default=6, help="real-time runs per point at most")
    ap.add_argument("--json", type=Path, help="also write the result here")
    ap.add_argument("--figure", type=Path, help="draw the curve here (PNG)")
    args = ap.parse_args()
    result = measure([int(x) for x in args.agents.split(",") if x], args.steps,
                     [int(x) for x in args.p000.split(",") if x], args.p000_steps, args.tries)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    if args.figure:
        figure(result, args.figure)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
