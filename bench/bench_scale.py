"""Paper 002's swarm at N spacecraft in batch mode: the cost of a spacecraft-step against N. Not a
test: the table goes to docs/scaling.md.

Each N runs what `swarmhil run SCENARIO --set dispersion.count=N --in-process --record truth` runs
(deploy.launcher.run_in_process(record="truth"), the batch mode: deploy/batch.py), twice: a short run
(`--short-steps` steps) and a long one (`--hours`, or longer for a small N: at least `--min-sc-steps`
spacecraft-steps); the cost per spacecraft-step is the difference
of their CPU seconds over the difference of their spacecraft-steps, so the start-up (scenario draw,
N controllers, the recording's set-up) is apart, in its own column (the short run's CPU). CPU is
this process's (`time.process_time`, the recorder's compression thread included), wall the run's.
Ratios are against the smallest N measured in the same invocation; the load average is printed at
the start and the end (the machine is shared). A figure of the cost against N is written with
`--figure PATH` (matplotlib, the `reports` extra).

    nice -n 10 .venv/bin/python bench/bench_scale.py --hours 1                        # rel, N = 20 100 300 1000
    nice -n 10 .venv/bin/python bench/bench_scale.py --sensing rel scene --hours 1 --compare-matrix \
        --figure docs/img/scaling.png                                                 # docs/scaling.md's table
    nice -n 10 .venv/bin/python bench/bench_scale.py --counts 1000 --hours 24          # the batch day of 1,000
    .venv/bin/python bench/bench_scale.py --pairs-only --counts 20 40 64 100 1000     # the neighbour search alone
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
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

SCENARIOS = {"rel": "sabatini-20.toml", "scene": "sabatini-20-camera-exact.toml"}
_TREE_FROM: dict[object, int] = {}  # each module's own TREE_MIN_COUNT, while the (N, N) forms are on


def matrix_forms(on: bool) -> None:
    """The plant's neighbour search by the (N, N) forms at every N (on), or by the spatial index from
    plant/sensors.py TREE_MIN_COUNT spacecraft (off): the comparison of `--compare-matrix`."""
    from swarmhil.plant import contact, scene_stimulus, sensors

    for module in (sensors, scene_stimulus, contact):
        if on:
            _TREE_FROM.setdefault(module, module.TREE_MIN_COUNT)
            module.TREE_MIN_COUNT = 10**9
        elif module in _TREE_FROM:
            module.TREE_MIN_COUNT = _TREE_FROM.pop(module)


def one(scenario: Path, count: int, steps: int, tmp: Path) -> dict[str, float]:
    """CPU and wall seconds of one batch run of `steps` steps with `count` spacecraft."""
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    c0, w0 = time.process_time(), time.monotonic()
    sc = load_scenario(scenario, [f"dispersion.count={count}"])
    sc = sc.with_overrides(duration_s=steps * sc.step_s)
    out = tmp / f"n{count}-{steps}"
    res = run_in_process(sc, out, "scale", record="truth")
    cpu, wall = time.process_time() - c0, time.monotonic() - w0
    assert (res.summary.get("batch") or {}).get("used"), res.summary.get("batch")
    mb = (out / "run.mcap").stat().st_size / 1e6
    (out / "run.mcap").unlink()
    return {"cpu_s": cpu, "wall_s": wall, "steps": steps, "mcap_mb": mb,
            "contacts": int((res.summary.get("contact") or {}).get("contacts", 0))}


def per_step(scenario: Path, n: int, hours: float, short_steps: int, tmp: Path,
             min_sc_steps: int = 0) -> dict[str, float]:
    """The short and the long run of N (at least `min_sc_steps` spacecraft-steps: a small swarm flies
    longer, so that its CPU is not a fraction of a second); the marginal CPU per spacecraft-step."""
    short = one(scenario, n, short_steps, tmp)
    steps = max(int(round(hours * 3600.0 / 10.0)), -(-min_sc_steps // n))
    long = one(scenario, n, steps, tmp)
    per = (long["cpu_s"] - short["cpu_s"]) / (n * (steps - short_steps))
    return {"n": n, "steps": steps, "startup_cpu_s": short["cpu_s"], "cpu_s": long["cpu_s"],
            "wall_s": long["wall_s"], "us_per_sc_step": per * 1e6, "mcap_mb": long["mcap_mb"],
            "contacts": long["contacts"], "day_min": (per * n * 8640 + short["cpu_s"]) / 60.0}


def measure(scenario: Path, counts: list[int], hours: float, short_steps: int,
            compare_matrix: bool = False, min_sc_steps: int = 0) -> list[dict[str, float]]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-scale-") as d:
        tmp = Path(d)
        one(scenario, counts[0], 2, tmp)  # every module loaded before the first figure
        for n in counts:
            row = per_step(scenario, n, hours, short_steps, tmp, min_sc_steps)
            if compare_matrix:  # the same N with the (N, N) forms, right after
                matrix_forms(True)
                try:
                    row["matrix_us_per_sc_step"] = per_step(scenario, n, hours, short_steps, tmp, min_sc_steps)["us_per_sc_step"]
                finally:
                    matrix_forms(False)
            rows.append(row)
            print(json.dumps(row), flush=True)
    base = rows[0]["us_per_sc_step"]
    for r in rows:
        r["ratio"] = r["us_per_sc_step"] / base
        if "matrix_us_per_sc_step" in r:
            r["matrix_ratio"] = r["matrix_us_per_sc_step"] / base
    return rows


def table(rows: list[dict[str, float]], sensing: str) -> str:
    matrix = "matrix_us_per_sc_step" in rows[0]
    extra = " | with the (N, N) forms (ratio) |" if matrix else " |"
    out = [f"| N ({sensing}) | steps | CPU per spacecraft-step | ratio to N = {rows[0]['n']}{extra} start-up CPU | "
           "CPU of the run | wall of the run | run.mcap | contacts | a day (8,640 steps), CPU |",
           "|---:" * (11 if matrix else 10) + "|"]
    for r in rows:
        m = f" {r['matrix_us_per_sc_step']:.1f} us ({r['matrix_ratio']:.2f}) |" if matrix else ""
        out.append(f"| {r['n']} | {r['steps']} | {r['us_per_sc_step']:.1f} us | {r['ratio']:.2f} |{m} "
                   f"{r['startup_cpu_s']:.1f} s | {r['cpu_s']:.1f} s | {r['wall_s']:.1f} s | {r['mcap_mb']:.1f} MB | "
                   f"{r['contacts']} | {r['day_min']:.1f} min |")
    return "\n".join(out)


def figure(results: dict[str, list[dict[str, float]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for sensing, rows in results.items():
        line, = ax.plot([r["n"] for r in rows], [r["us_per_sc_step"] for r in rows], "o-", label=f"sensing {sensing}")
        if "matrix_us_per_sc_step" in rows[0]:
            ax.plot([r["n"] for r in rows], [r["matrix_us_per_sc_step"] for r in rows], "s--", color=line.get_color(),
                    alpha=0.6, label=f"sensing {sensing}, (N, N) neighbour search")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("spacecraft N")
    ax.set_ylabel("CPU per spacecraft-step (us)")
    ax.set_title("Paper 002's swarm in batch mode (--in-process --record truth)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    print(f"figure: {path}")


def pairs_only(counts: list[int]) -> None:
    """The neighbour search alone (plant/sensors.py visible_pairs), the k-d tree against the (N, N) matrix,
    on a string of N spacecraft 200 m apart as the dispersion draws them (best of 5 x 200 calls)."""
    import timeit

    import numpy as np

    from swarmhil.plant.sensors import CameraGeometry, visible_pairs

    cam, rng = CameraGeometry(), np.random.default_rng(1)
    print("| N | k-d tree | (N, N) matrix | tree / matrix |\n|---:|---:|---:|---:|")
    for n in counts:
        pos = np.c_[rng.normal(0, 30, n), np.arange(n) * 200.0 + rng.normal(0, 40, n), rng.normal(0, 30, n)]
        t = [min(timeit.repeat(lambda: visible_pairs(pos, cam, None, tree=tree), number=200, repeat=5)) / 200
             for tree in (True, False)]
        print(f"| {n} | {t[0] * 1e6:.0f} us | {t[1] * 1e6:.0f} us | {t[0] / t[1]:.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--counts", type=int, nargs="+", default=[20, 100, 300, 1000])
    ap.add_argument("--sensing", nargs="+", choices=sorted(SCENARIOS), default=["rel"])
    ap.add_argument("--hours", type=float, default=2.0, help="simulated hours of the long run of each N")
    ap.add_argument("--short-steps", type=int, default=10, help="steps of the start-up run of each N")
    ap.add_argument("--figure", type=Path, default=None, help="write the cost against N here (PNG)")
    ap.add_argument("--min-sc-steps", type=int, default=200_000,
                    help="each long run flies at least this many spacecraft-steps (more steps for a small N)")
    ap.add_argument("--compare-matrix", action="store_true",
                    help="also run each N with the (N, N) neighbour search (no spatial index), right after")
    ap.add_argument("--pairs-only", action="store_true", help="time the neighbour search alone, tree against matrix")
    args = ap.parse_args()
    print(f"load average at start: {os.getloadavg()}", flush=True)
    if args.pairs_only:
        pairs_only(sorted(args.counts))
        return
    results = {}
    for sensing in args.sensing:
        rows = measure(ROOT / "deploy" / "scenarios" / SCENARIOS[sensing], sorted(args.counts), args.hours,
                       args.short_steps, args.compare_matrix, args.min_sc_steps)
        results[sensing] = rows
        print(table(rows, sensing), flush=True)
    print(f"load average at end: {os.getloadavg()}", flush=True)
    if args.figure is not None:
        figure(results, args.figure)


if __name__ == "__main__":
    main()
