"""100 agent processes over Zenoh in lockstep (issue 16: 24 h in <= 10 min, <= 60 MB RSS per agent).

    python bench/bench_100.py [--hours 24] [--scenario deploy/scenarios/sabatini-100.toml] [--no-floor]

Runs `python -m swarmhil.deploy.cli run SCENARIO --duration HOURS*3600` once, sampling every process's RSS
(bench/agent_rss.py `measure`), then the bus floor of the same number of processes and steps
(bench/bus_floor.py) in the same invocation. Prints the launcher wall, the plant loop, the bus floor
and their ratio, the median and maximum agent peak RSS (sampled and VmHWM), dead agents and missed
deadlines, and the load average at start and end. The last line is the result as JSON. The machine
is shared: only the ratio to the floor of the same invocation says much about speed.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

from agent_rss import measure
from bench_backbone import bus_floor, load


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default=str(ROOT / "deploy/scenarios/sabatini-100.toml"))
    ap.add_argument("--hours", type=float, default=24.0, help="simulated hours")
    ap.add_argument("--no-floor", action="store_true", help="skip the bus floor")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    out = a.out or Path(tempfile.mkdtemp(prefix="bench-100-"))
    r: dict = {"load_start": load(), "hours": a.hours}
    print(f"load average at start: {r['load_start']}", flush=True)
    t0 = time.perf_counter()
    rss = measure(ROOT, a.scenario, a.hours * 3600.0, out)
    r["launcher_wall_s"] = time.perf_counter() - t0
    s = json.loads((out / "run" / "summary.json").read_text())
    r.update(agents=s["agents"], steps=s["steps"], loop_wall_s=s["loop_wall_s"], dead_agents=s["dead_agents"],
             missed_deadlines=s["missed_deadlines"], late_commands=s["late_commands"],
             agent_rss_median_mb=rss["agent_median_mb"], agent_rss_max_mb=rss["agent_max_mb"],
             agent_vmhwm_median_mb=rss["agent_vmhwm_median_mb"], plant_mb=rss["plant_mb"],
             recorder_mb=rss["recorder_mb"], launcher_mb=rss["launcher_mb"])
    r["load_after_run"] = load()
    print(f"{r['agents']} agents, {r['steps']} steps ({a.hours:g} h): launcher wall {r['launcher_wall_s']:.1f} s, "
          f"plant loop {r['loop_wall_s']:.1f} s ({r['loop_wall_s'] / r['steps'] * 1e3:.1f} ms/step); "
          f"dead agents {len(r['dead_agents'])}, missed deadlines {len(r['missed_deadlines'])}", flush=True)
    print(f"agent peak RSS: median {r['agent_rss_median_mb']:.1f} MB, max {r['agent_rss_max_mb']:.1f} MB "
          f"(VmHWM median {r['agent_vmhwm_median_mb']:.1f} MB); plant {r['plant_mb']:.1f}, recorder "
          f"{r['recorder_mb']:.1f}, launcher {r['launcher_mb']:.1f} MB", flush=True)
    if not a.no_floor:
        r["bus_floor_s"] = bus_floor(r["agents"], r["steps"])
        r["loop_over_bus_floor"] = r["loop_wall_s"] / r["bus_floor_s"]
        print(f"bus floor ({r['agents']} workers, {r['steps']} steps): {r['bus_floor_s']:.1f} s; "
              f"plant loop / floor {r['loop_over_bus_floor']:.2f}, launcher wall / floor "
              f"{r['launcher_wall_s'] / r['bus_floor_s']:.2f}", flush=True)
    r["load_end"] = load()
    print(f"load average at start {r['load_start']}, after the run {r['load_after_run']}, at end {r['load_end']}")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
