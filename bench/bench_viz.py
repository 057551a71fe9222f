"""Cost of the viewer bridge: lockstep wall time with and without `--viz save` (issue 6; goal <= 10 %).

The same `swarmhil run SCENARIO --duration D --no-progress` invocation, alternately without and
with `--viz save`, `--repeats` times each. The stepping wall time of a run is read from its
recording: reception time of the first to the last clock tick (process start-up, which the viewer
does not change, is left out); the launcher's total wall time is reported too. The ratio is of
the medians, measured in this one invocation. The CPU time of every process of the run (start-up
included) is compared too: on a shared, loaded machine it is steadier than wall time.

    .venv/bin/python bench/bench_viz.py [--scenario deploy/scenarios/sabatini-20.toml] [--duration 7200] [--repeats 3]

Writes bench/results/bench_viz.json.

The bridge's own cost per step, old code against new (`--logger RUN_DIR/run.mcap --trees A B`):
`swarmhil replay` of one recording to a .rrd, run with each source tree as the working directory
(so that tree's dashboards/ is imported), alternately, `--repeats` times; the CPU time of the
replay process after its imports (every thread: Rerun encodes on its own), divided by the truth
steps. The replay feeds the recording through the same logger as the live
bridge.

    .venv/bin/python bench/bench_viz.py --logger RUN_DIR/run.mcap --trees /path/to/old-checkout . [--repeats 3]
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def stepping_wall_s(mcap_path: Path) -> tuple[float, int]:
    """(last - first reception time of the clock, number of ticks) from the recording: the
    reception wall time is publish_time (log_time is simulation time, DESIGN.md MCAP contract)."""
    from mcap.reader import make_reader

    times = []
    with open(mcap_path, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages():
            if ch.topic == "clock" or ch.topic.endswith("/clock"):
                times.append(m.publish_time)
    return (max(times) - min(times)) / 1e9, len(times)


def one_run(scenario: str, duration_s: float, viz: bool, work: Path, i: int) -> dict:
    out = work / f"{'viz' if viz else 'plain'}-{i}"
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", scenario, "--duration", str(duration_s), "--mode", "lockstep",
           "--no-progress", "--out", str(out)] + (["--viz", "save"] if viz else [])
    t0 = time.monotonic()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=1800)
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{r.stdout}{r.stderr}")
    summary = json.loads((out / "summary.json").read_text())
    step_s, ticks = stepping_wall_s(out / "run.mcap")
    v = summary.get("viz") or {}
    return {"viz": viz, "stepping_wall_s": step_s, "ticks": ticks, "launcher_wall_s": summary["wall_s"],
            "cli_wall_s": time.monotonic() - t0,
            # CPU of every process of the run (the CLI and all it waited for), start-up included
            "run_cpu_s": (ru1.ru_utime + ru1.ru_stime) - (ru0.ru_utime + ru0.ru_stime),
            "viz_process_cpu_s": v.get("process_cpu_s"), "viz_flush_cpu_s": v.get("flush_cpu_s")}


LOGGER_CODE = """
import resource, sys
from swarmhil.dashboards.replay import replay
ru = resource.getrusage(resource.RUSAGE_SELF)
c0 = ru.ru_utime + ru.ru_stime
st = replay(sys.argv[1], sys.argv[2])
ru = resource.getrusage(resource.RUSAGE_SELF)
print(ru.ru_utime + ru.ru_stime - c0, st["last_step"] + 1)
"""


def logger_cpu(tree: Path, mcap: Path, rrd: Path) -> tuple[float, int]:
    """(CPU seconds after the imports, truth steps) of one `replay` with `tree` as the working directory."""
    r = subprocess.run([sys.executable, "-c", LOGGER_CODE, str(mcap), str(rrd)], cwd=tree,
                       capture_output=True, text=True, timeout=1800)
    if r.returncode != 0:
        raise RuntimeError(f"replay in {tree} failed:\n{r.stderr}")
    cpu, steps = r.stdout.split()[-2:]
    return float(cpu), int(steps)


def bench_logger(mcap: Path, trees: list[Path], repeats: int, out: Path) -> None:
    rows: dict[str, list[float]] = {str(t): [] for t in trees}
    steps = 0
    with tempfile.TemporaryDirectory(prefix="swarmhil-bench-viz-") as tmp:
        for i in range(repeats):
            for t in trees:   # alternate, so drifts in machine load hit both alike
                cpu, steps = logger_cpu(t, mcap, Path(tmp) / f"{i}.rrd")
                rows[str(t)].append(cpu)
                print(f"{t}: replay CPU {cpu:.2f} s, {steps} steps, {1e6 * cpu / steps:.0f} us/step", flush=True)
    med = {t: statistics.median(v) for t, v in rows.items()}
    base = med[str(trees[0])]
    result = {"mcap": str(mcap), "steps": steps, "repeats": repeats, "cpu_s": rows,
              "median_us_per_step": {t: 1e6 * m / steps for t, m in med.items()},
              "ratio_to_first": {t: m / base for t, m in med.items()}}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    print("median CPU per step: " + "; ".join(f"{t} {1e6 * m / steps:.0f} us ({m / base:.2f}x)" for t, m in med.items())
          + f"; wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logger", type=Path, help="RUN_DIR/run.mcap: time the logger (replay) instead of whole runs")
    ap.add_argument("--trees", type=Path, nargs="+", default=[ROOT], help="--logger: source trees to compare")
    ap.add_argument("--scenario", default=str(ROOT / "deploy" / "scenarios" / "sabatini-20.toml"))
    ap.add_argument("--duration", type=float, default=7200.0, help="simulated seconds per run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "bench_viz.json"))
    a = ap.parse_args()
    if a.logger:
        out = Path(a.out) if a.out != ap.get_default("out") else ROOT / "bench" / "results" / "bench_viz_logger.json"
        bench_logger(a.logger.resolve(), [t.resolve() for t in a.trees], a.repeats, out)
        return
    runs = []
    with tempfile.TemporaryDirectory(prefix="swarmhil-bench-viz-") as tmp:
        for i in range(a.repeats):
            for viz in (False, True):   # alternate, so drifts in machine load hit both alike
                r = one_run(a.scenario, a.duration, viz, Path(tmp), i)
                runs.append(r)
                print(f"{'with --viz save' if viz else 'without viz    '}  stepping {r['stepping_wall_s']:7.2f} s "
                      f"({r['ticks']} ticks)  launcher {r['launcher_wall_s']:7.2f} s  run CPU {r['run_cpu_s']:7.2f} s"
                      + (f"  (viz process {r['viz_process_cpu_s']:.2f} s)" if viz else ""), flush=True)
    med = {v: statistics.median(r["stepping_wall_s"] for r in runs if r["viz"] is v) for v in (False, True)}
    med_l = {v: statistics.median(r["launcher_wall_s"] for r in runs if r["viz"] is v) for v in (False, True)}
    med_c = {v: statistics.median(r["run_cpu_s"] for r in runs if r["viz"] is v) for v in (False, True)}
    pairs = [runs[i + 1]["stepping_wall_s"] / runs[i]["stepping_wall_s"] for i in range(0, len(runs), 2)]
    result = {
        "scenario": a.scenario, "duration_s": a.duration, "repeats": a.repeats,
        "median_stepping_wall_s": {"without": med[False], "with_viz_save": med[True]},
        "ratio_stepping": med[True] / med[False],
        "median_launcher_wall_s": {"without": med_l[False], "with_viz_save": med_l[True]},
        "ratio_launcher": med_l[True] / med_l[False],
        "paired_ratios_stepping": pairs,
        "median_run_cpu_s": {"without": med_c[False], "with_viz_save": med_c[True]},
        "ratio_run_cpu": med_c[True] / med_c[False],
        "median_viz_process_cpu_s": statistics.median(r["viz_process_cpu_s"] for r in runs if r["viz"]),
        "goal": "ratio_stepping <= 1.10",
        "runs": runs,
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1))
    print(f"stepping wall time with/without --viz save: {result['ratio_stepping']:.3f} "
          f"(medians {med[True]:.2f} s / {med[False]:.2f} s; paired ratios {', '.join(f'{x:.2f}' for x in pairs)}); "
          f"launcher wall {result['ratio_launcher']:.3f}; run CPU {result['ratio_run_cpu']:.3f} "
          f"(viz process {result['median_viz_process_cpu_s']:.2f} s of {med_c[True]:.1f} s); wrote {a.out}")


if __name__ == "__main__":
    main()
