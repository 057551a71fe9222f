"""In-process wall time of a scenario from two source trees, interleaved in one invocation (issue 16).

    python bench/bench_inprocess.py --base /tmp/base [--tree .] [--duration 7200] [--repeats 2] [--record truth] [SCENARIO]

Runs `run_in_process` of SCENARIO (default sabatini-20) alternately from the tree under test and
from a base tree (e.g. `git archive <commit> | tar -x -C /tmp/base`), each in a fresh Python
process, and prints per-run wall, CPU and plant-loop seconds, their medians and minima and the ratios
base / tree (the CPU time and the minimum are the least disturbed by other load). `--record truth`
runs the batch mode (deploy/batch.py) instead of every message.
The machine is shared: only the ratio within one invocation means anything; the load average is
printed with it. Both trees must give the same total dV (it is printed and checked).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CODE = r"""
import json, sys, time
sys.path.insert(0, '.')
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario
from swarmhil.plant.node import PlantNode
_run, loop_cpu = PlantNode.run, []
def _timed(self, *a, **k):
    c = time.process_time()
    try:
        return _run(self, *a, **k)
    finally:
        loop_cpu.append(time.process_time() - c)
PlantNode.run = _timed
sc = load_scenario(sys.argv[1]).with_overrides(duration_s=float(sys.argv[2]))
t0, c0 = time.perf_counter(), time.process_time()
res = run_in_process(sc, __import__('pathlib').Path(sys.argv[3]), 'bench', record=sys.argv[4])
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
print(json.dumps({'wall_s': wall, 'cpu_s': cpu, 'loop_cpu_s': loop_cpu[0], 'loop_s': res.summary['loop_wall_s'], 'dv': res.summary['delta_v_total_mps']}))
"""


def one(tree: Path, scenario: str, duration: float, out: Path, record: str = "all") -> dict:
    p = subprocess.run([sys.executable, "-c", CODE, str(Path(scenario).resolve()), str(duration), str(out), record],
                       cwd=tree, capture_output=True, text=True, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    root = Path(__file__).resolve().parent.parent
    ap.add_argument("scenario", nargs="?", default=str(root / "deploy/scenarios/sabatini-20.toml"))
    ap.add_argument("--base", required=True, type=Path)
    ap.add_argument("--tree", type=Path, default=Path(__file__).resolve().parent.parent)
    ap.add_argument("--duration", type=float, default=7200.0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--record", choices=("all", "truth"), default="all", help="truth: the batch mode")
    a = ap.parse_args()
    load0 = Path("/proc/loadavg").read_text().split()[:3]
    res: dict[str, list[dict]] = {"base": [], "tree": []}
    with tempfile.TemporaryDirectory() as d:
        for r in range(a.repeats):
            for name, tree in (("base", a.base), ("tree", a.tree)):
                x = one(tree.resolve(), a.scenario, a.duration, Path(d) / f"{name}{r}", a.record)
                res[name].append(x)
                print(f"{name} #{r}: wall {x['wall_s']:.2f} s, CPU {x['cpu_s']:.2f} s, plant loop {x['loop_s']:.2f} s "
                      f"(CPU {x['loop_cpu_s']:.2f} s), "
                      f"dV {x['dv']!r}", flush=True)
    load1 = Path("/proc/loadavg").read_text().split()[:3]
    same = {x["dv"] for v in res.values() for x in v}
    for label, agg in (("median", statistics.median), ("min", min)):
        m = {k: {q: agg(x[q] for x in v) for q in ("wall_s", "cpu_s", "loop_s", "loop_cpu_s")} for k, v in res.items()}
        print(f"{label}: wall base {m['base']['wall_s']:.2f} s / tree {m['tree']['wall_s']:.2f} s = "
              f"{m['base']['wall_s'] / m['tree']['wall_s']:.2f}x; CPU {m['base']['cpu_s']:.2f} / {m['tree']['cpu_s']:.2f} s = "
              f"{m['base']['cpu_s'] / m['tree']['cpu_s']:.2f}x; plant loop wall {m['base']['loop_s'] / m['tree']['loop_s']:.2f}x, "
              f"CPU {m['base']['loop_cpu_s']:.2f} / {m['tree']['loop_cpu_s']:.2f} s = {m['base']['loop_cpu_s'] / m['tree']['loop_cpu_s']:.2f}x")
    print(f"load average at start {' '.join(load0)}, at end {' '.join(load1)}; total dV identical: {len(same) == 1}")


if __name__ == "__main__":
    main()
