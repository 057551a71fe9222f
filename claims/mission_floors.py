"""docs/performance.md "Batch run ÷ vectorised floor, papers 000, 001, 003 and 004" (issue 29):
`bench/bench_batch_missions.py --floors` in one invocation: for tersoff-6 (3000 s), surround-6 and
servicing-6 (60 s; 600 steps each), capture-10 and capture-20 (60 s; 1200 steps each), five
interleaved pairs of the mission's vectorised floor
(bench/mission_floors.py) and its in-process batch run (`record="truth"`), the medians of the loop
times and of the per-pair ratios. Tier `bench`: timings of this machine at that moment, checked for
presence and shape only; `swarmhil claims --bench --only floors. --record && swarmhil claims
--write` regenerates the table (about 8 min here).

The table's correctness column, the floor's agreement with the batch run's truth at the same
horizons, is not a timing: it comes from one floor and one batch run per mission
(`floors.truth`, tier `all`, about 20 s of CPU), checked as residuals within the bounds
tests/test_mission_floors.py states (1e-9 relative in dV, 1e-6 m in the final positions).
"""
from __future__ import annotations

from typing import Any

from swarmhil.claims.model import Claim, Row, Source, Table, Tol
from swarmhil.claims.runs import bench_script

DOC = "docs/performance.md"
SHAPE = Tol(shape_only=True)
REPEATS = 5
MISSIONS = (("p004", "servicing-6"), ("p003", "surround-6"), ("p001", "tersoff-6"), ("p000_10", "capture-10"),
            ("p000_20", "capture-20"))
# (result field, claim suffix, words, format)
FIELDS = (("floor_loop_median_s", "floor", "the floor's loop, median [s]", ".3f"),
          ("batch_loop_median_s", "batch", "the batch run's plant loop, median [s]", ".3f"),
          ("batch_run_median_s", "run", "the whole batch run_in_process, median [s]", ".3f"),
          ("batch_over_floor_median", "ratio", "batch loop ÷ floor loop, median of the pairs", ".2f"),
          ("batch_over_floor_min", "ratio_min", "batch loop ÷ floor loop, smallest pair", ".2f"),
          ("batch_run_over_floor_median", "run_ratio", "whole batch run ÷ floor loop, median of the pairs", ".2f"),
          )
# the floor against the batch run's truth: (result field, claim suffix, words, format, bound)
TRUTH_FIELDS = (("floor_dv_rel_diff", "dv_diff", "|floor total dV ÷ batch total dV - 1|", ".1g", 1e-9),
                ("floor_position_diff_m", "pos_diff", "largest |floor - truth| of the final positions [m]", ".1g", 1e-6))


def flat(result: dict[str, Any], fields: tuple[tuple[Any, ...], ...] = FIELDS) -> dict[str, float]:
    """{paper}.{suffix} -> value, and the load averages."""
    out = {f"{paper}.{f[1]}": float(result["missions"][name][f[0]]) for paper, name in MISSIONS for f in fields}
    return {**out, "load_start": float(result["load_start"]), "load_end": float(result["load_end"])}


def _measure(_get: Any) -> dict[str, Any]:
    return flat(bench_script("bench_batch_missions").measure_floors([name for _, name in MISSIONS], REPEATS))


def _truth(_get: Any) -> dict[str, Any]:
    """One floor and one batch run per mission (the bench's horizons): the floor against the truth."""
    return flat(bench_script("bench_batch_missions").measure_floors([name for _, name in MISSIONS], 1), TRUTH_FIELDS)


SOURCES = [Source("floors.missions", "bench", _measure,
                  f"python bench/bench_batch_missions.py --floors --repeats {REPEATS} (one invocation, ~8 min)"),
           Source("floors.truth", "all", _truth,
                  "python bench/bench_batch_missions.py --floors --repeats 1 (the floor-vs-truth column)")]
CLAIMS = [Claim(f"floors.{paper}.{suffix}", "floors.missions", (lambda k: lambda s: s[k])(f"{paper}.{suffix}"),
                SHAPE, f"{name}: {words}", fmt)
          for paper, name in MISSIONS for _, suffix, words, fmt in FIELDS]
CLAIMS += [Claim(f"floors.{paper}.{suffix}", "floors.truth", (lambda k: lambda s: s[k])(f"{paper}.{suffix}"),
                 Tol(abs=bound), f"{name}: {words}", fmt, residual=True)
           for paper, name in MISSIONS for _, suffix, words, fmt, bound in TRUTH_FIELDS]
CLAIMS += [Claim(f"floors.{k}", "floors.missions", (lambda k: lambda s: s[k])(k), SHAPE, f"load average (1 min), {k}",
                 ".1f") for k in ("load_start", "load_end")]

LABEL = {"servicing-6": ("servicing-6 (paper 004, 60 s: 600 steps)", ("004", "60", "600")),
         "surround-6": ("surround-6 (paper 003, 60 s: 600 steps)", ("003", "60", "600")),
         "tersoff-6": ("tersoff-6 (paper 001, 3000 s: 600 steps)", ("001", "3000", "600")),
         "capture-10": ("capture-10 (paper 000, 60 s: 1200 steps)", ("000", "60", "1200")),
         "capture-20": ("capture-20 (paper 000, 60 s: 1200 steps)", ("000", "60", "1200"))}
ROWS = tuple(Row((LABEL[name][0], *(f"{{floors.{paper}.{s}}}" for s in ("floor", "batch", "run", "ratio", "ratio_min",
                                                                         "run_ratio")),
                  f"{{floors.{paper}.dv_diff}}, {{floors.{paper}.pos_diff}} m"), params=LABEL[name][1])
             for paper, name in MISSIONS)
LOAD = Row(("load average (1 min) at the start → end", "{floors.load_start} → {floors.load_end}", "", "", "", "", "", ""),
           params=("1",))
TABLES = [Table("mission-floors", DOC, ("scenario", "floor loop s", "batch loop s", "whole batch run s",
                                        "batch ÷ floor (median)", "smallest pair", "whole run ÷ floor",
                                        "floor vs truth: dV (relative), positions"),
                (*ROWS, LOAD), measured=(1, 2, 3, 4, 5, 6, 7),
                align=("---", "---:", "---:", "---:", "---:", "---:", "---:", "---:"))]
