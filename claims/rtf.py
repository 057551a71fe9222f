"""docs/performance.md "The real-time-factor curve" (issue 29): `bench/rtf_curve.py` in one
invocation: paper 002 with N = 1, 5, 10, 20, 50, 100, 200 agent processes (ideal sensing, 10 s
steps, 60 steps) and paper 000 with N = 5, 10, 20 (20 Hz, 200 steps), each in lockstep, in real time
at the largest speed-up without a missed deadline, and the bus contract's floor of the same N and
steps. Tier `bench`: timings of this machine at that moment, checked for presence and shape only;
`swarmhil claims --bench --only rtf. --record` regenerates the table and redraws
docs/img/rtf_curve.png from the same measurement (about 25 min here).
"""
from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType
from typing import Any

from swarmhil.claims.model import Claim, Row, Source, Table, Tol

DOC = "docs/performance.md"
ROOT = Path(__file__).resolve().parent.parent
FIGURE = ROOT / "docs/img/rtf_curve.png"
SHAPE = Tol(shape_only=True)
P002_AGENTS = (1, 5, 10, 20, 50, 100, 200)
P002_STEPS = 60
P000_AGENTS = (5, 10, 20)
P000_STEPS = 200
TRIES = 6
# (result field, claim suffix, format)
FIELDS = (("rtf_lockstep", "lock", "s3"), ("realtime_speed_no_miss", "rt", "s3"), ("rtf_floor", "floor", "s3"),
          ("lockstep_over_floor", "ratio", ".2g"))


def bench_module() -> ModuleType:
    """bench/rtf_curve.py (bench/ is not a package)."""
    spec = importlib.util.spec_from_file_location("rtf_curve", ROOT / "bench/rtf_curve.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def flat(result: dict[str, Any]) -> dict[str, Any]:
    """{paper}.n{N}.{suffix} -> value; no speed without misses within the tries is 0."""
    return {f"{paper}.n{p['agents']}.{suffix}": float(p[field] or 0.0)
            for paper in ("p002", "p000") for p in result[paper] for field, suffix, _ in FIELDS}


def _measure(_get: Any) -> dict[str, Any]:
    mod = bench_module()
    result = mod.measure(list(P002_AGENTS), P002_STEPS, list(P000_AGENTS), P000_STEPS, TRIES)
    mod.figure(result, FIGURE)
    print(f"rtf.curve: load averages {result['load_start']} -> {result['load_end']}, {result['wall_s']:.0f} s wall")
    return flat(result)


SOURCES = [Source("rtf.curve", "bench", _measure,
                  "python bench/rtf_curve.py --figure docs/img/rtf_curve.png (one invocation, ~25 min)")]
POINTS = [("p002", n) for n in P002_AGENTS] + [("p000", n) for n in P000_AGENTS]
CLAIMS = [Claim(f"rtf.{paper}.n{n}.{suffix}", "rtf.curve", (lambda k: lambda s: s[k])(f"{paper}.n{n}.{suffix}"),
                SHAPE, f"real-time factor, paper {paper[1:]}, {n} agents: {field}", fmt)
          for paper, n in POINTS for field, suffix, fmt in FIELDS]

LABEL = {"p002": "paper 002, ideal sensing, 10 s steps", "p000": "paper 000, 20 Hz"}
ROWS = tuple(Row((f"{LABEL[paper]}: {n}",
                  *("{rtf." + f"{paper}.n{n}.{suffix}" + "}" for _, suffix, _ in FIELDS)), params=())
             for paper, n in POINTS)
TABLES = [Table("rtf-curve", DOC, ("case: agents (one OS process each)", "lockstep (×)",
                                   "real time without a missed deadline (×)", "contract floor (×)",
                                   "lockstep step ÷ floor step"), ROWS, measured=(1, 2, 3, 4))]
