"""Papers 001, 003 and 004 in-process: the per-agent path against the batch path, side by side in one
invocation, as ratios per-agent / batch of CPU time (issue 29); with `--floors`, papers 000, 001, 003
and 004: the batch run against the mission's vectorised floor. Not a test: figures go to
docs/performance.md.

Both paths run `deploy.launcher.run_in_process(record="truth")` on the same scenario and duration:
the per-agent one with the batch mode off (`opts={"batch": False}`: one agent node per spacecraft,
stimuli, commands and packets as messages on the in-memory bus, the link channel companion: what
every mission run did before issue 29), the batch one through deploy/batch.py `BatchHook` (the
plant hands the stimuli over, `step_batch` decides, `BatchLink` carries the packets). Each run is
checked to give the same total dV to the last bit. A one-step run of each mission first loads
every module, so import time is in neither figure. CPU is this process's (`time.process_time`);
wall beside it carries the load (printed at the start and the end).

With `--floors`, each mission's batch run against its vectorised floor instead (bench/mission_floors.py:
the same scenario, law and dynamics in one numpy loop): `--repeats` alternations of floor, batch run
in this process (each preceded by nothing but the last: the machine is shared, so the pairs are
interleaved and the medians reported), the ratio of the batch run's plant loop (`loop_wall_s`, what
bench/bench_backbone.py compares for paper 002) and of the whole `run_in_process` (start-up and
recorder close included) to the floor's loop, per pair; the floor's total dV and final positions
are checked against the batch run's truth (relative dV difference and metres printed). `make bench`
runs this after bench/bench_backbone.py.

With `--before COMMIT`, each mission is also run on that commit's tree (exported with `git
archive`, this venv, its own subprocess: a one-step warm-up run, then the measured run in the same
process) with `record="truth"`, which before issue 29 took the per-agent path for these missions:
the ratio before / batch is what a campaign of the mission gains.

    nice -n 10 .venv/bin/python bench/bench_batch_missions.py
    nice -n 10 .venv/bin/python bench/bench_batch_missions.py --before 2421385
    nice -n 10 .venv/bin/python bench/bench_batch_missions.py --missions servicing-6 --duration-scale 6
    nice -n 10 .venv/bin/python bench/bench_batch_missions.py --floors --repeats 5
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

# scenario -> simulated seconds of the default measurement (600 steps each)
MISSIONS = {"servicing-6": 60.0, "surround-6": 60.0, "tersoff-6": 3000.0}
# --floors: these and paper 000's two cases (1200 steps each: capture-10 searches for its first 22 s)
FLOOR_MISSIONS = {**MISSIONS, "capture-10": 60.0, "capture-20": 60.0}


def _run(sc, out: Path, batch: bool) -> tuple[float, float, dict]:
    from swarmhil.deploy.launcher import run_in_process

    w0, c0 = time.perf_counter(), time.process_time()
    res = run_in_process(sc, out, "bench", record="truth", opts=None if batch else {"batch": False})
    return time.process_time() - c0, time.perf_counter() - w0, res.summary


# run in another tree's subprocess: a warm-up step, then the measured run (CPU of that run only)
_JOB = """
import json, sys, tempfile, time
from pathlib import Path
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario
sc = load_scenario(sys.argv[1])
with tempfile.TemporaryDirectory() as tmp:
    run_in_process(sc.with_overrides(duration_s=sc.step_s), Path(tmp) / "warm", "bench", record="truth")
    sc = sc.with_overrides(duration_s=float(sys.argv[2]))
    w0, c0 = time.perf_counter(), time.process_time()
    res = run_in_process(sc, Path(tmp) / "run", "bench", record="truth")
    print(json.dumps({"cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0,
                      "dv": res.summary["delta_v_total_mps"], "batch": res.summary.get("batch")}))
"""


# one p004 servicer's `step` (what an agent process runs at 10 Hz), 400 steps of random measurements
_SERVICER_STEP = """
import json, time
import numpy as np
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.missions.p004_lbdnn.fsw.controller import make_servicer
from swarmhil.missions.p004_lbdnn.contract import KEY_D, KEY_Y
c = make_servicer("s1", OrbitInfo(6878137.0, 0.0011), {"graph": "ring", "seed": 0})
rng = np.random.default_rng(1)
def obs(k):
    extra = {f"{KEY_D}/{j}": rng.normal(0, 100, 3) for j in c.cfg.neighbours}
    extra[f"{KEY_Y}/defunct"] = rng.normal(0, 100, c.cfg.c_matrix.shape[0])
    return Observation(step=k, t_s=0.1 * k, u_rad=0.0, neighbour_ids=[], rel_position_m=np.zeros((0, 3)),
                       rel_velocity_mps=np.zeros((0, 3)), extra=extra)
o = [obs(k) for k in range(400)]
c0 = time.process_time()
for x in o:
    c.step(x)
print(json.dumps({"ms_per_step": (time.process_time() - c0) / len(o) * 1e3}))
"""


def _servicer_step_ms(tree: Path) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _SERVICER_STEP], cwd=tree, env=env, capture_output=True, text=True,
                         check=True).stdout
    return float(json.loads(out.strip().splitlines()[-1])["ms_per_step"])


def _before(tree: Path, scenario: Path, duration_s: float) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _JOB, str(scenario), str(duration_s)], cwd=tree, env=env,
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def floor_pairs(name: str, sc, repeats: int, tmp: Path) -> dict:
    """`repeats` alternations of the mission's floor and its batch run (after one warm-up step of
    each); the times, their medians, the ratios per pair and the floor's agreement with the truth."""
    import numpy as np

    from swarmhil.dashboards.truth_io import read_truth
    from mission_floors import floor

    floor(sc.with_overrides(duration_s=sc.step_s))
    _run(sc.with_overrides(duration_s=sc.step_s), tmp / f"{name}-warm", True)
    fl, loop, run = [], [], []
    for k in range(repeats):
        f = floor(sc)
        _cpu, wall, sb = _run(sc, tmp / f"{name}-b{k}", True)
        assert sb["batch"]["used"] is True, sb["batch"]
        fl.append(f["loop_s"])
        loop.append(sb["loop_wall_s"])
        run.append(wall)
    truth = read_truth(tmp / f"{name}-b{repeats - 1}" / "run.mcap")
    ratio = [b / f for b, f in zip(loop, fl)]
    ratio_run = [b / f for b, f in zip(run, fl)]
    med = statistics.median
    return {"scenario": name, "simulated_s": sc.duration_s, "steps": sc.steps, "repeats": repeats,
            "floor_loop_s": fl, "batch_loop_s": loop, "batch_run_wall_s": run,
            "floor_loop_median_s": med(fl), "batch_loop_median_s": med(loop), "batch_run_median_s": med(run),
            "batch_over_floor_median": med(ratio), "batch_over_floor_min": min(ratio),
            "batch_run_over_floor_median": med(ratio_run),
            "floor_dv_rel_diff": abs(f["dv_total_mps"] / sb["delta_v_total_mps"] - 1.0),
            "floor_position_diff_m": float(np.abs(f["position_m"] - truth.position_m[-1]).max())}


def measure_floors(missions: list[str], repeats: int, duration_scale: float = 1.0) -> dict:
    """Every mission's `floor_pairs` in one invocation, with the load average at the start and the end."""
    from swarmhil.deploy.scenario import load_scenario

    out: dict = {"load_start": os.getloadavg()[0], "missions": {}}
    with tempfile.TemporaryDirectory(prefix="bench-floors-") as tmp:
        for name in missions:
            sc = load_scenario(ROOT / "deploy" / "scenarios" / f"{name}.toml")
            sc = sc.with_overrides(duration_s=FLOOR_MISSIONS[name] * duration_scale)
            r = out["missions"][name] = floor_pairs(name, sc, repeats, Path(tmp))
            print(f"  {name} ({r['steps']} steps): floor loop {r['floor_loop_median_s']:.3f} s, batch loop "
                  f"{r['batch_loop_median_s']:.3f} s (whole run {r['batch_run_median_s']:.3f} s): batch ÷ floor "
                  f"{r['batch_over_floor_median']:.2f} (median of {repeats}, min {r['batch_over_floor_min']:.2f}; "
                  f"whole run {r['batch_run_over_floor_median']:.2f}); floor vs truth: dV {r['floor_dv_rel_diff']:.1e} "
                  f"relative, positions {r['floor_position_diff_m']:.1e} m", flush=True)
    out["load_end"] = os.getloadavg()[0]
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--missions", nargs="*", default=None,
                    help="scenarios (names, or one comma-separated list); default: every mission of the mode")
    ap.add_argument("--duration-scale", type=float, default=1.0, help="times each mission's default duration")
    ap.add_argument("--before", default=None, help="also run each mission on this commit's tree (record truth)")
    ap.add_argument("--floors", action="store_true", help="batch run against the vectorised floor (bench/mission_floors.py)")
    ap.add_argument("--repeats", type=int, default=5, help="--floors: alternations of floor and batch run")
    a = ap.parse_args()
    missions = [m for arg in a.missions for m in arg.split(",") if m] if a.missions is not None else None
    if a.floors:
        print(f"batch run ÷ vectorised floor, papers 000, 001, 003, 004 (load average {os.getloadavg()[0]:.2f})", flush=True)
        res = measure_floors(missions or list(FLOOR_MISSIONS), a.repeats, a.duration_scale)
        print(json.dumps({k: v for k, v in res.items()}))
        return
    from swarmhil.deploy.scenario import load_scenario

    print(json.dumps({"load_start": os.getloadavg()}))
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        tree = None
        if a.before:
            tree = Path(tmp) / "before"
            tree.mkdir()
            archive = subprocess.run(["git", "-C", str(ROOT), "archive", a.before], capture_output=True, check=True).stdout
            subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
        for name in missions or list(MISSIONS):
            sc = load_scenario(ROOT / "deploy" / "scenarios" / f"{name}.toml")
            warm = sc.with_overrides(duration_s=sc.step_s)
            _run(warm, Path(tmp) / f"{name}-warm-a", False)
            _run(warm, Path(tmp) / f"{name}-warm-b", True)
            sc = sc.with_overrides(duration_s=MISSIONS[name] * a.duration_scale)
            cpu_a, wall_a, sa = _run(sc, Path(tmp) / f"{name}-agents", False)
            cpu_b, wall_b, sb = _run(sc, Path(tmp) / f"{name}-batch", True)
            assert sa["batch"]["used"] is False and sb["batch"]["used"] is True, (sa["batch"], sb["batch"])
            assert sa["delta_v_total_mps"] == sb["delta_v_total_mps"], (sa["delta_v_total_mps"], sb["delta_v_total_mps"])
            row = {"scenario": name, "simulated_s": sc.duration_s, "steps": sc.steps,
                   "per_agent_cpu_s": round(cpu_a, 3), "batch_cpu_s": round(cpu_b, 3),
                   "per_agent_wall_s": round(wall_a, 3), "batch_wall_s": round(wall_b, 3),
                   "cpu_ratio_per_agent_over_batch": round(cpu_a / cpu_b, 2),
                   "batch_cpu_ms_per_step": round(1e3 * cpu_b / sc.steps, 3), "same_delta_v": True}
            if tree is not None:
                b = _before(tree, ROOT / "deploy" / "scenarios" / f"{name}.toml", sc.duration_s)
                row.update({"before": a.before, "before_batch": b["batch"], "before_cpu_s": round(b["cpu_s"], 3),
                            "before_wall_s": round(b["wall_s"], 3), "cpu_ratio_before_over_batch": round(b["cpu_s"] / cpu_b, 2),
                            "before_delta_v_rel_diff": abs(b["dv"] - sb["delta_v_total_mps"]) / abs(sb["delta_v_total_mps"])})
            print(json.dumps(row))
        if tree is not None:  # an agent process's cost: one servicer's step, alternately in both trees
            now, before = [], []
            for _ in range(3):
                now.append(_servicer_step_ms(ROOT))
                before.append(_servicer_step_ms(tree))
            print(json.dumps({"p004_servicer_step_ms": round(min(now), 3), "before_p004_servicer_step_ms": round(min(before), 3)}))
    print(json.dumps({"load_end": os.getloadavg()}))


if __name__ == "__main__":
    main()
