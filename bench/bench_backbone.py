"""`make bench` (issues 2 and 16): every speed ratio of the run modes, in one invocation.

    make bench     # or: .venv/bin/python bench/bench_backbone.py [--hours 24] [--camera-hours 2] [--repeats 3]

For drift-20 and sabatini-20 (ideal sensing) and sabatini-20-camera-filter (rendered camera + EKF):

- multi-process lockstep (20 agent processes over Zenoh): plant loop and launcher wall, against the
  bus floor of the same number of processes and steps (bench/bus_floor.py: empty tick and reply);
  for the ideal scenarios also the *contract floor* (`bus_floor.py --contract`: the run's own
  messages per step, a clock, the truth, 20 stimuli, 20 commands, 20 telemetry, one listener, with
  no decoding and no work, with the message sizes the run itself recorded: `--sizes-from`) and the
  run's loop ÷ that floor, and for the camera scenario the *compute floor* (the CPU of its
  in-process run spread over every core: no multi-process run can beat it on this machine);
- the CPU per step of each process kind of the multi-process run over its loop (bench/mp_cpu.py),
  beside the contract floor's (`bus_floor.py --cpu`: workers for the agents, the listener for the
  recorder, the coordinator with the router for the plant);
- in-process batch mode (`run_in_process(record="truth")`, deploy/batch.py), against the
  vectorised floor (bench/vectorised_floor.py: the same plant and control law in one numpy loop,
  written independently of the node code) for the ideal-sensing scenarios, alternated `--repeats`
  times (min and median of the ratios); the floor's total dV is checked equal to the run's;
- in-process with every message (`record="all"`, one agent node per spacecraft), once, for reference.

The machine is shared: only ratios within one invocation mean anything; the load average at the
start and the end is printed with them. `--hours` shortens every run (the same for all modes of a
scenario); `--camera-hours` that of the camera scenario (its 24 h multi-process run takes tens of
minutes on a loaded machine). The last line is the whole result as JSON.
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

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

IDEAL = ("drift-20", "sabatini-20")
CAMERA = "sabatini-20-camera-filter"
CORES = len(os.sched_getaffinity(0))


def load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def floor(n: int, steps: int, contract: bool = False, sizes_from: Path | None = None, cpu: bool = False) -> dict:
    """bench/bus_floor.py's result (`--json`: wall_s, sizes, cpu_ms_per_step): `contract`, the bus
    contract's own messages per step, with the message sizes of the recording `sizes_from`."""
    args = [*(["--contract"] if contract else []), *(["--sizes-from", str(sizes_from)] if sizes_from else []),
            *(["--cpu"] if cpu else [])]
    fl = subprocess.run([sys.executable, str(ROOT / "bench/bus_floor.py"), "--workers", str(n), "--steps", str(steps),
                         "--json", *args], capture_output=True, text=True, check=True)
    return json.loads(fl.stdout.splitlines()[-1])


def bus_floor(n: int, steps: int, contract: bool = False) -> float:
    """Wall seconds of bench/bus_floor.py (`contract`: the bus contract's own messages per step)."""
    return float(floor(n, steps, contract)["wall_s"])


def multi_process(path: str, sc, out: Path, duration: float) -> dict:
    """The launcher's run with every process's CPU over the loop (bench/mp_cpu.py): launcher wall,
    loop wall, total dV and CPU ms per step summed per process kind."""
    from mp_cpu import kinds, run_with_cpu

    t0 = time.perf_counter()
    try:
        m = run_with_cpu(path, sc, out, f"bench-mp-{sc.name}", duration)
    except RuntimeError as exc:
        raise RuntimeError(f"multi-process {sc.name}: {exc}") from exc
    by_kind = {k: {"n": len(v), "sum": sum(v)} for k, v in kinds(m["cpu_ms_per_step"]).items()}
    return {"launcher_s": time.perf_counter() - t0, "loop_s": m["summary"]["loop_wall_s"],
            "dv": m["summary"]["delta_v_total_mps"], "cpu_ms_per_step": by_kind}


def in_process(sc, out: Path, record: str) -> dict:
    from swarmhil.deploy.launcher import run_in_process

    t0, c0 = time.perf_counter(), time.process_time()
    res = run_in_process(sc, out, f"bench-ip-{record}", record=record)
    return {"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0, "loop_s": res.summary["loop_wall_s"],
            "dv": res.summary["delta_v_total_mps"], "batch": (res.summary.get("batch") or {}).get("used", False)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=24.0, help="simulated hours of the ideal-sensing scenarios")
    ap.add_argument("--camera-hours", type=float, default=None, help="simulated hours of the camera scenario (default --hours)")
    ap.add_argument("--repeats", type=int, default=3, help="in-process batch / vectorised floor alternations")
    ap.add_argument("--scenarios", default=",".join((*IDEAL, CAMERA)))
    ap.add_argument("--no-multi-process", action="store_true", help="only the in-process ratios")
    ap.add_argument("--no-in-process", action="store_true", help="only the multi-process ratios (and the bus floor)")
    a = ap.parse_args()
    from swarmhil.deploy.scenario import load_scenario
    from vectorised_floor import floor_run

    names = [s for s in a.scenarios.split(",") if s]
    out = Path(tempfile.mkdtemp(prefix="swarmhil-bench-"))
    result: dict = {"load_start": load(), "scenarios": {}}
    print(f"load average at start: {result['load_start']}", flush=True)
    for name in names:
        path = str(ROOT / "deploy/scenarios" / f"{name}.toml")
        hours = a.camera_hours if (name == CAMERA and a.camera_hours is not None) else a.hours
        duration = hours * 3600.0
        sc = load_scenario(path).with_overrides(duration_s=duration)
        steps, n = sc.steps, len(sc.ids)
        r: dict = {"hours": hours, "steps": steps, "agents": n}
        if not a.no_multi_process:
            try:
                r["multi_process"] = multi_process(path, sc, out / f"mp-{name}", duration)
            except RuntimeError as exc:  # a loaded machine can starve start-up: said, and the rest goes on
                r["multi_process_error"] = str(exc).splitlines()[0][:300]
                print(f"  {name}: {r['multi_process_error']}", flush=True)
            else:
                r["bus_floor_s"] = bus_floor(n, steps)
                r["multi_process_over_bus_floor"] = r["multi_process"]["loop_s"] / r["bus_floor_s"]
                r["multi_process_launcher_over_bus_floor"] = r["multi_process"]["launcher_s"] / r["bus_floor_s"]
                if name in IDEAL:  # what the contract's traffic alone costs (no decoding, no work, no recording),
                    # with this run's own message sizes
                    cf = floor(n, steps, contract=True, sizes_from=out / f"mp-{name}" / "run.mcap", cpu=True)
                    r["contract_floor_s"], r["contract_floor_cpu_ms_per_step"] = cf["wall_s"], cf["cpu_ms_per_step"]
                    r["contract_floor_sizes"] = cf["sizes"]
                    r["contract_floor_over_bus_floor"] = r["contract_floor_s"] / r["bus_floor_s"]
                    r["multi_process_over_contract_floor"] = r["multi_process"]["loop_s"] / r["contract_floor_s"]
        if a.no_in_process:
            pass
        elif name in IDEAL:
            pairs = []
            for k in range(a.repeats):
                f = floor_run(sc)
                b = in_process(sc, out / f"ipb-{name}", "truth")
                if not b["batch"]:
                    raise RuntimeError(f"{name}: the in-process run did not use the batch mode")
                if f["dv_total_mps"] != b["dv"]:
                    raise RuntimeError(f"{name}: the vectorised floor's total dV {f['dv_total_mps']!r} differs from the run's {b['dv']!r}")
                pairs.append((f, b))
                print(f"  {name} #{k}: floor loop {f['loop_s']:.2f} s, batch loop {b['loop_s']:.2f} s (whole run {b['wall_s']:.2f} s), "
                      f"ratio {b['loop_s'] / f['loop_s']:.2f}", flush=True)
            ratios = [b["loop_s"] / f["loop_s"] for f, b in pairs]
            r["vectorised_floor_s"] = [f["loop_s"] for f, _ in pairs]
            r["in_process_batch"] = [b for _, b in pairs]
            r["in_process_over_vectorised_floor"] = {"min": min(ratios), "median": statistics.median(ratios)}
            r["in_process_run_over_vectorised_floor"] = {
                "min": min(b["wall_s"] / f["loop_s"] for f, b in pairs),
                "median": statistics.median(b["wall_s"] / f["loop_s"] for f, b in pairs)}
            r["dv_equal_to_floor"] = True
        else:
            r["in_process_batch"] = [in_process(sc, out / f"ipb-{name}", "truth")]
            if "bus_floor_s" in r:  # the same flight software and plant in one process, spread over every core
                r["compute_floor_s"] = r["in_process_batch"][0]["cpu_s"] / CORES
                r["compute_floor_over_bus_floor"] = r["compute_floor_s"] / r["bus_floor_s"]
        if not a.no_in_process:
            r["in_process_messages"] = in_process(sc, out / f"ipm-{name}", "all")
        result["scenarios"][name] = r
        print_scenario(name, r)
    result["load_end"] = load()
    print(f"\nload average at start {result['load_start']}, at end {result['load_end']}")
    print(json.dumps(result))


def print_scenario(name: str, r: dict) -> None:
    steps = r["steps"]
    print(f"\n{name}: {r['agents']} agents, {steps} steps ({r['hours']:g} h simulated)")
    print(f"{'what':62s} {'wall s':>8s} {'ms/step':>8s} {'ratio':>7s}")
    row = lambda what, v, ratio="": print(f"{what:62s} {v:8.2f} {v / steps * 1e3:8.3f} {ratio:>7s}")  # noqa: E731
    if "multi_process" in r:
        fl = r["bus_floor_s"]
        row("bus floor (empty tick/reply, same processes and steps)", fl, "1.00")
        row("multi-process lockstep, plant loop  (÷ bus floor)", r["multi_process"]["loop_s"], f"{r['multi_process_over_bus_floor']:.2f}")
        row("multi-process lockstep, launcher wall incl. start-up (÷ bus floor)", r["multi_process"]["launcher_s"],
            f"{r['multi_process_launcher_over_bus_floor']:.2f}")
        if "contract_floor_s" in r:
            row("contract floor (the run's messages per step, no work) (÷ bus floor)", r["contract_floor_s"],
                f"{r['contract_floor_over_bus_floor']:.2f}")
            row("multi-process lockstep, plant loop ÷ contract floor", r["multi_process"]["loop_s"],
                f"{r['multi_process_over_contract_floor']:.2f}")
        print_cpu(r)
        if "compute_floor_s" in r:
            row(f"compute floor: in-process CPU (with start-up) ÷ {CORES} cores (÷ bus floor)", r["compute_floor_s"],
                f"{r['compute_floor_over_bus_floor']:.2f}")
    if "vectorised_floor_s" in r:
        fl = min(r["vectorised_floor_s"])
        row("vectorised floor (numpy, one loop; min of the repeats)", fl, "1.00")
        best = min(r["in_process_batch"], key=lambda b: b["loop_s"])
        q = r["in_process_over_vectorised_floor"]
        row("in-process batch, plant loop (÷ floor: min / median)", best["loop_s"], f"{q['min']:.2f}")
        print(f"{'':62s} {'':8s} {'':8s} {q['median']:7.2f}")
        row("in-process batch, whole run incl. start-up (÷ floor, min)", best["wall_s"],
            f"{r['in_process_run_over_vectorised_floor']['min']:.2f}")
    elif "in_process_batch" in r:
        b = r["in_process_batch"][0]
        row(f"in-process, record truth (batch mode used: {b['batch']})", b["loop_s"])
    if "in_process_messages" in r:
        row("in-process, every message recorded (one agent node per spacecraft)", r["in_process_messages"]["loop_s"])


# the contract floor's process that stands for each process kind of the run (bench/bus_floor.py --cpu)
FLOOR_KIND = {"agent": "workers", "recorder": "listener", "plant": "coordinator + router"}


def print_cpu(r: dict) -> None:
    """CPU ms per step of each process kind of the multi-process run (over its loop), beside the
    contract floor's process that does that kind's messaging (the floor's coordinator is the plant and
    the router in one process)."""
    run = r["multi_process"].get("cpu_ms_per_step")
    if not run:
        return
    fl = r.get("contract_floor_cpu_ms_per_step") or {}
    print(f"{'CPU ms per step (loop only), process kind':44s} {'n':>3s} {'run':>8s}   contract floor")
    for k, v in sorted(run.items(), key=lambda kv: -kv[1]["sum"]):
        f = FLOOR_KIND.get(k)
        print(f"{k:44s} {v['n']:3d} {v['sum']:8.3f}   " + (f"{fl[f]:8.3f} ({f})" if f in fl else ""))
    floor_total = sum(v for k, v in fl.items() if k != "worker")  # ("worker": one of "workers")
    print(f"{'total':44s} {'':3s} {sum(v['sum'] for v in run.values()):8.3f}   " + (f"{floor_total:8.3f}" if fl else ""))


if __name__ == "__main__":
    main()
