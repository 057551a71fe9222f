"""docs/performance.md "Paper 000 in-process" (issue 29): in one invocation,
each job in its own subprocess (bench/bench_p000.py `run_side`), one after the other,

- 60 s of case (ii) (capture-20, 1 200 steps): the tree before issue 29 (a8239fd, `git archive`d,
  its in-process run with every message) and this tree's batch mode (`record="truth"`); CPU and
  wall of each and the ratio before ÷ now;
- the whole 550 s of case (i) (capture-10) and case (ii) (capture-20) in this tree's batch mode:
  wall and CPU time of `run_in_process` (start-up of the run included, imports not).

Tier `bench`: timings of this machine at that moment, checked for presence and shape only;
`swarmhil claims --bench --only p000speed. --record && swarmhil claims --write` regenerates the
table (about 3 min on a quiet machine).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from swarmhil.claims.model import Claim, Row, Source, Table, Tol
from swarmhil.claims.runs import bench_script

DOC = "docs/performance.md"
ROOT = Path(__file__).resolve().parent.parent
SHAPE = Tol(shape_only=True)
CASES = (("c20_60_before", "capture-20", 60.0, "before"), ("c20_60", "capture-20", 60.0, "now"),
         ("c10_550", "capture-10", 550.0, "now"), ("c20_550", "capture-20", 550.0, "now"))


def _measure(_get: Any) -> dict[str, float]:
    bench = bench_script("bench_p000")
    out: dict[str, float] = {"load_start": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory(prefix="claims-p000speed-") as d:
        before = bench.export(bench.BEFORE, Path(d))
        for key, name, duration, tree in CASES:
            a = SimpleNamespace(fits=1, outliers=0.1, room_duration=1.0, scenario=f"deploy/scenarios/{name}.toml",
                                duration=duration, record="all" if tree == "before" else "truth")
            r = bench.run_side(before if tree == "before" else ROOT, "run", a)
            if tree == "now" and not (r.get("batch") or {}).get("used"):
                raise RuntimeError(f"{name}: the batch mode was not used: {r.get('batch')}")
            out[f"{key}.cpu"], out[f"{key}.wall"] = float(r["cpu_s"]), float(r["wall_s"])
    out["c20_60.ratio_cpu"] = out["c20_60_before.cpu"] / out["c20_60.cpu"]
    out["c20_60.ratio_wall"] = out["c20_60_before.wall"] / out["c20_60.wall"]
    out["load_end"] = os.getloadavg()[0]
    return out


SOURCES = [Source("p000speed.runs", "bench", _measure,
                  "python bench/bench_p000.py --worker run, on a8239fd and on this tree (one invocation, ~3 min)")]
KEYS = ([(f"{k}.{m}", f"{name} {dur:.0f} s, {tree}: {m} [s]", ".1f") for k, name, dur, tree in CASES for m in ("cpu", "wall")]
        + [("c20_60.ratio_cpu", "capture-20 60 s: CPU before ÷ now", ".2f"),
           ("c20_60.ratio_wall", "capture-20 60 s: wall before ÷ now", ".2f"),
           ("load_start", "load average (1 min) at the start", ".1f"), ("load_end", "load average (1 min) at the end", ".1f")])
CLAIMS = [Claim(f"p000speed.{k}", "p000speed.runs", (lambda k: lambda s: s[k])(k), SHAPE, words, fmt)
          for k, words, fmt in KEYS]
ROWS = (Row(("case (ii), capture-20, 60 s (1 200 steps): a8239fd (the tree before batch mode for paper 000), every message",
             "{p000speed.c20_60_before.cpu}", "{p000speed.c20_60_before.wall}", ""), params=("60", "1200")),
        Row(("the same in this tree's batch mode (`--record truth`)", "{p000speed.c20_60.cpu}", "{p000speed.c20_60.wall}",
             "×{p000speed.c20_60.ratio_cpu} CPU, ×{p000speed.c20_60.ratio_wall} wall"), params=()),
        Row(("case (i), capture-10, the whole 550 s, batch mode", "{p000speed.c10_550.cpu}", "{p000speed.c10_550.wall}",
             "≤ 30 s wall"), params=("550", "30")),
        Row(("case (ii), capture-20, the whole 550 s, batch mode", "{p000speed.c20_550.cpu}", "{p000speed.c20_550.wall}",
             "≤ 60 s wall"), params=("550", "60")),
        Row(("load average (1 min) at the start → end", "{p000speed.load_start} → {p000speed.load_end}", "", ""),
            params=("1",)))
TABLES = [Table("p000-speed", DOC, ("run (in-process)", "CPU s", "wall s", "goal / ratio"), ROWS,
                measured=(1, 2, 3), align=("---", "---:", "---:", "---"))]
