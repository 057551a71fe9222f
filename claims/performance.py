"""docs/performance.md "Where the time of an in-process run goes": the profile of one 2 h in-process
run of sabatini-20 (720 steps, 20 agents, full recording), in the tree before issue 16's first
round (d1d8223) and in this tree, one invocation (tier `bench`: timings of this machine at that
moment, checked for presence and shape only; `swarmhil claims --bench --only perf. --record`
regenerates the table).

The profiler counts CPU time of the process (`cProfile.Profile(time.process_time)`), not wall
time, so another process's load changes the figures less than it did the wall-clock profiles the
page once showed; the profiler still inflates every Python call.
"""
from __future__ import annotations

import os
import pstats
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from swarmhil.claims.model import Claim, Row, Source, Table, Tol

DOC = "docs/performance.md"
ROOT = Path(__file__).resolve().parent.parent
BEFORE = "d1d8223"  # main before issue 16's first round
DURATION_S = 7200.0
SHAPE = Tol(shape_only=True)
DRIVER = """
import cProfile, runpy, sys, time
out = sys.argv[1]
sys.argv = ["swarmhil", *sys.argv[2:]]
pr = cProfile.Profile(time.process_time)
pr.enable()
try:
    runpy.run_module("swarmhil.deploy.cli", run_name="__main__")
except SystemExit:
    pass
pr.disable()
pr.dump_stats(out)
"""
# (row key, the function(s) whose cumulative CPU time the row is: file path suffix, function name); paper
# 002's law and DRE gains were agent/behaviour/{sabatini,dre}.py before, missions/p002_sabatini/fsw/ now
ROWS: tuple[tuple[str, str, tuple[tuple[str, str], ...]], ...] = (
    ("loop", "plant loop (720 steps), all of the below", (("plant/node.py", "run"),)),
    ("agents", "agents: stimulus handling (decode, flight software, command and telemetry)",
     (("agent/node.py", "_on_stimulus"),)),
    ("ctl", "of which the `sabatini` controller step", (("/sabatini.py", "step"),)),
    ("decode", "decode + validation of every received message (agents and plant)", (("bus/codec.py", "decode"),)),
    ("rec", "recorder: MCAP write, incl. the Foxglove scene of every truth", (("bus/recorder.py", "_on_sample"),)),
    ("mcap", "of which the MCAP writer's `add_message` (pure Python: `mcap`'s `Writer` before, `bus/mcap_writer.py` "
     "now)", (("mcap/writer.py", "add_message"), ("bus/mcap_writer.py", "add_message"))),
    ("rel", "plant: `rel` stimulus construction", (("plant/sensing/builtin.py", "stimulus"),)),
    ("cmd", "plant: command decode and command box", (("plant/node.py", "_on_command"),)),
    ("dre-gain", "DRE gain lookup (`GainTable.gain` before, `interpolate_periodic` now)",
     (("/dre.py", "gain"), ("/dre.py", "interpolate_periodic"))),
    ("dre-table", "DRE gain tables (solve, or read from the disk cache)", (("/dre.py", "gain_table"),)),
    ("scenario", "scenario load and validation", (("deploy/scenario.py", "load_scenario"),)),
)


def cumulative(stats: pstats.Stats, funcs: tuple[tuple[str, str], ...]) -> float:
    """The cumulative time of the named functions (summed over same-named entries of a file)."""
    tot = 0.0
    for (path, _line, name), (_cc, _nc, _tt, ct, _callers) in stats.stats.items():  # type: ignore[attr-defined]
        if any(path.endswith(p) and name == n for p, n in funcs):
            tot += ct
    return tot


def profile(tree: Path) -> dict[str, Any]:
    """Profile `swarmhil run deploy/scenarios/sabatini-20.toml --in-process --duration 7200` in `tree`."""
    with tempfile.TemporaryDirectory(prefix="claims-prof-") as d:
        prof = Path(d) / "run.prof"
        env = {**os.environ, "PYTHONPATH": str(tree)}
        load0 = os.getloadavg()[0]
        r = subprocess.run([sys.executable, "-c", DRIVER, str(prof), "run", "deploy/scenarios/sabatini-20.toml",
                            "--in-process", "--duration", str(DURATION_S), "--out", str(Path(d) / "run"),
                            "--no-progress"], cwd=tree, env=env, capture_output=True, text=True, timeout=3600)
        if r.returncode != 0 or not prof.is_file():
            raise RuntimeError(f"profile in {tree}: exit {r.returncode}: {r.stderr[-500:]}")
        st = pstats.Stats(str(prof))
        out = {k: cumulative(st, f) for k, _, f in ROWS}
        out["mcap_calls"] = sum(nc for (p, _l, n), (_cc, nc, *_r) in st.stats.items()  # type: ignore[attr-defined]
                                if p.endswith("mcap/writer.py") and n == "add_message"
                                or p.endswith("bus/mcap_writer.py") and n == "add_message")
        out["load_start"], out["load_end"] = load0, os.getloadavg()[0]
        return out


def _before(_get: Any) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="claims-base-") as d:
        archive = subprocess.run(["git", "archive", BEFORE], cwd=ROOT, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", d], input=archive, check=True)
        return profile(Path(d))


SOURCES = [Source("perf.before", "bench", _before, f"the profile of the 2 h in-process run in `git archive {BEFORE}`"),
           Source("perf.now", "bench", lambda _get: profile(ROOT), "the profile of the 2 h in-process run in this tree")]


def _c(src: str, key: str, what: str, fmt: str = ".2f") -> Claim:
    return Claim(f"perf.{src}.{key}", f"perf.{src}", (lambda k: lambda s: float(s[k]))(key), SHAPE, what, fmt)


CLAIMS = [_c(src, k, f"{src}: {label} [CPU s]") for src in ("before", "now") for k, label, _ in ROWS]
CLAIMS += [_c(src, k, f"{src}: {k}", ".0f") for src in ("before", "now") for k in ("load_start", "load_end")]
CLAIMS += [_c("now", "mcap_calls", "now: mcap add_message calls", ",.0f")]


def _row(key: str, label: str) -> Row:
    label = label.replace("(pure Python:", "({perf.now.mcap_calls} messages, pure Python:")
    return Row((label, f"{{perf.before.{key}}}", f"{{perf.now.{key}}}"), params=("720",))


LOAD = Row(("load average (1 min) at the start → end of the profile", "{perf.before.load_start} → "
            "{perf.before.load_end}", "{perf.now.load_start} → {perf.now.load_end}"), params=("1",))
TABLES = [Table("performance-profile", DOC, ("where", f"before ({BEFORE}) CPU s", "this tree CPU s"),
                (*[_row(k, lab) for k, lab, _ in ROWS], LOAD), measured=(1, 2), align=("---", "---:", "---:"))]
