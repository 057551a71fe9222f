"""Papers 001, 003 and 004 in-process: the per-agent path against the batch path, side by side in one
invocation, as ratios per-agent / batch of CPU time (issue 29). Not a test: figures go to
docs/performance.md.

Both paths run `deploy.launcher.run_in_process(record="truth")` on the same scenario and duration:
the per-agent one with the batch mode off (`opts={"batch": False}`: one agent node per spacecraft,
stimuli, commands and packets as messages on the in-memory bus, the link channel companion: what
every mission run did before issue 29), the batch one through deploy/batch.py `BatchHook` (the
plant hands the stimuli over, `step_batch` decides, `BatchLink` carries the packets). Each run is
checked to give the same total dV to the last bit. A one-step run of each mission first loads
every module, so import time is in neither figure. CPU is this process's (`time.process_time`);
wall beside it carries the load (printed at the start and the end).

    nice -n 10 .venv/bin/python bench/bench_batch_missions.py
    nice -n 10 .venv/bin/python bench/bench_batch_missions.py --missions servicing-6 --duration-scale 6
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# scenario -> simulated seconds of the default measurement (600 steps each)
MISSIONS = {"servicing-6": 60.0, "surround-6": 60.0, "tersoff-6": 3000.0}


def _run(sc, out: Path, batch: bool) -> tuple[float, float, dict]:
    from deploy.launcher import run_in_process

    w0, c0 = time.perf_counter(), time.process_time()
    res = run_in_process(sc, out, "bench", record="truth", opts=None if batch else {"batch": False})
    return time.process_time() - c0, time.perf_counter() - w0, res.summary


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--missions", nargs="*", default=list(MISSIONS))
    ap.add_argument("--duration-scale", type=float, default=1.0, help="times each mission's default duration")
    a = ap.parse_args()
    from deploy.scenario import load_scenario

    print(json.dumps({"load_start": os.getloadavg()}))
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        for name in a.missions:
            sc = load_scenario(ROOT / "deploy" / "scenarios" / f"{name}.toml")
            warm = sc.with_overrides(duration_s=sc.step_s)
            _run(warm, Path(tmp) / f"{name}-warm-a", False)
            _run(warm, Path(tmp) / f"{name}-warm-b", True)
            sc = sc.with_overrides(duration_s=MISSIONS[name] * a.duration_scale)
            cpu_a, wall_a, sa = _run(sc, Path(tmp) / f"{name}-agents", False)
            cpu_b, wall_b, sb = _run(sc, Path(tmp) / f"{name}-batch", True)
            assert sa["batch"]["used"] is False and sb["batch"]["used"] is True, (sa["batch"], sb["batch"])
            assert sa["delta_v_total_mps"] == sb["delta_v_total_mps"], (sa["delta_v_total_mps"], sb["delta_v_total_mps"])
            print(json.dumps({"scenario": name, "simulated_s": sc.duration_s, "steps": sc.steps,
                              "per_agent_cpu_s": round(cpu_a, 3), "batch_cpu_s": round(cpu_b, 3),
                              "per_agent_wall_s": round(wall_a, 3), "batch_wall_s": round(wall_b, 3),
                              "cpu_ratio_per_agent_over_batch": round(cpu_a / cpu_b, 2),
                              "batch_cpu_ms_per_step": round(1e3 * cpu_b / sc.steps, 3),
                              "same_delta_v": True}))
    print(json.dumps({"load_end": os.getloadavg()}))


if __name__ == "__main__":
    main()
