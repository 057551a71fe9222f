"""What a mesh of routers adds to a multi-process lockstep run (`swarmhil run --hosts K`, deploy/mesh.py):
per-step wall and CPU of the same scenario with one router and with K routers on loopback, alternated
in one invocation so the machine's load drifts over both alike.

    python bench/mesh_overhead.py deploy/scenarios/sabatini-20.toml --duration 3600 --hosts 4 --rounds 3 [--netns]

Each round runs `--hosts 1` then `--hosts K` (same run id and seed) with bench/mp_cpu.py's
`run_with_cpu` (every process's CPU from /proc over the plant's loop, start-up and shutdown left
out), and checks that both recorded the same truth. Prints one row per run (loop wall per step, the
plant's wait for the commands per step, CPU per step of routers, agents and all processes), the
medians per K with the difference, and the result as JSON on the last line.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from mp_cpu import run_with_cpu  # noqa: E402


def truth_bytes(mcap: Path) -> list[bytes]:
    """The recorded truth messages' bytes, in order (the two placements must agree)."""
    from mcap.reader import make_reader

    with open(mcap, "rb") as f:
        return [m.data for _s, ch, m in make_reader(f).iter_messages() if ch.topic == "truth"]


def one_run(scenario: str, sc, out: Path, run: str, duration: float, hosts: int, netns: bool = False) -> dict:
    opts = {"hosts": hosts, "netns": netns} if hosts > 1 else {}
    m = run_with_cpu(scenario, sc, out, run, duration, opts=opts)
    cpu = m["cpu_ms_per_step"]
    timing = m["summary"].get("plant_timing_s", {})
    steps_all = max(1, int(m["summary"].get("steps", 1)))
    s = m["summary"]
    return {"hosts": hosts, "steps": m["steps"], "wall_ms_per_step": m["wall_ms_per_step"],
            "wait_ms_per_step": 1e3 * timing.get("wait_and_propagate_s", float("nan")) / steps_all,
            "router_cpu_ms_per_step": sum(v for n, v in cpu.items() if n.startswith("router")),
            "agent_cpu_ms_per_step": sum(v for n, v in cpu.items() if n.startswith("agent-")),
            "total_cpu_ms_per_step": sum(cpu.values()),
            "dead": len(s.get("dead_agents", {})), "missed": len(s.get("missed_deadlines", {})),
            "late": int(s.get("late_commands", 0))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario")
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--hosts", type=int, default=4, help="K: the mesh's number of hosts (routers)")
    ap.add_argument("--rounds", type=int, default=3, help="pairs of runs (1 router, then K)")
    ap.add_argument("--out", help="directory for the runs (default: a temporary one)")
    ap.add_argument("--netns", action="store_true", help="the K hosts' runs with --netns (network namespaces; root)")
    a = ap.parse_args()
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(a.scenario).with_overrides(duration_s=a.duration)
    base = Path(a.out or tempfile.mkdtemp(prefix="swarmhil-mesh-"))
    load0 = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    rows: list[dict] = []
    cols = ("wall_ms_per_step", "wait_ms_per_step", "router_cpu_ms_per_step", "agent_cpu_ms_per_step",
            "total_cpu_ms_per_step")
    print(f"{sc.name}: {len(sc.ids)} agents, {sc.steps} steps of {sc.step_s:g} s; 1 router vs {a.hosts} routers"
          f"{' in network namespaces' if a.netns else ''}, "
          f"{a.rounds} rounds; load {load0}")
    print(f"{'round':>5s} {'hosts':>5s} {'wall ms/step':>12s} {'wait ms/step':>12s} {'routers CPU':>11s} "
          f"{'agents CPU':>10s} {'total CPU':>9s}  (CPU ms/step)  dead missed late")
    for r in range(a.rounds):
        truths = []
        for hosts in (1, a.hosts):
            out = base / f"r{r}-h{hosts}"
            try:
                row = one_run(a.scenario, sc, out, f"meshbench{r}", a.duration, hosts, a.netns and hosts > 1)
            except RuntimeError as exc:
                sys.exit(f"error: round {r}, --hosts {hosts}: {exc}")
            row["round"] = r
            rows.append(row)
            truths.append(truth_bytes(out / "run.mcap"))
            print(f"{r:5d} {hosts:5d} " + " ".join(f"{row[c]:{w}.2f}" for c, w in zip(cols, (12, 12, 11, 10, 9)))
                  + f"  {'':13s} {row['dead']:4d} {row['missed']:6d} {row['late']:4d}", flush=True)
        if truths[0] != truths[1]:
            sys.exit(f"error: round {r}: the truth with {a.hosts} routers differs from the one-router run's")
    med = {h: {c: statistics.median(x[c] for x in rows if x["hosts"] == h) for c in cols} for h in (1, a.hosts)}
    for h in (1, a.hosts):
        print(f"{'med':>5s} {h:5d} " + " ".join(f"{med[h][c]:{w}.2f}" for c, w in zip(cols, (12, 12, 11, 10, 9))))
    diff = {c: med[a.hosts][c] - med[1][c] for c in cols}
    print(f"{'diff':>5s} {'':5s} " + " ".join(f"{diff[c]:+{w}.2f}" for c, w in zip(cols, (12, 12, 11, 10, 9))))
    print(json.dumps({"scenario": sc.name, "agents": len(sc.ids), "steps": sc.steps, "hosts": a.hosts, "netns": a.netns,
                      "rounds": a.rounds, "load_start": load0, "median": {str(h): v for h, v in med.items()},
                      "mesh_minus_one_router": diff, "runs": rows, "out": str(base)}))


if __name__ == "__main__":
    main()
