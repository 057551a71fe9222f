"""Which doc tables must be claims tables (issue 24), and the explicit list of those not yet covered.

A required table is named by its doc and the heading it sits under. It is covered when the registry
renders it (`table` = its marker id). `NOT_YET` lists the tables that are not, each with why; the
test `tests/test_claims.py` fails if a listed table gets a marker (move it out of the list) or a
required table is neither covered nor listed, so the list can only shrink honestly.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Required:
    doc: str
    heading: str  # the heading line the table sits under (as written, without the #s)
    table: str | None  # marker id when covered
    why_not: str = ""  # when not covered yet: what it takes


BENCH = "timings (bench tier); not yet registered"

REQUIRED: tuple[Required, ...] = (
    Required("docs/paper002-reproduction.md", "Results", "paper002-results"),
    Required("docs/paper002-reproduction.md", "Navigation noise (section 5, Figs. 30-31): `runs/sweep-noise`",
             "paper002-noise"),
    Required("docs/paper002-reproduction.md", "Navigation noise (section 5, Figs. 30-31): `runs/sweep-noise`",
             "paper002-noise-seeds"),
    Required("docs/paper002-reproduction.md", "How dV depends on the initial dispersion (Table 1 is missing)",
             "paper002-dispersion"),
    Required("docs/paper002-reproduction.md", "How dV depends on the initial dispersion (Table 1 is missing)",
             "paper002-draws"),
    Required("docs/paper000-reproduction.md", "The paper's claims against the measurements", "paper000-repro"),
    Required("docs/paper000.md", "Paper vs measured", "paper000-numbers"),
    Required("docs/paper000.md", "Case (i) over the link, 550 s", "paper000-link"),
    Required("docs/paper001.md", "Paper vs measured", "paper001-verdicts"),
    Required("docs/paper001.md", "Paper vs measured", "paper001-paper"),
    Required("docs/paper001.md", "Paper vs measured", "paper001-centred"),
    Required("docs/paper001.md", "Paper vs measured", "paper001-literal"),
    Required("docs/paper001.md", "Paper vs measured", "paper001-ae"),
    Required("docs/paper001.md", "The claims table, checked on the stack (full tersoff-6, seed 1, 5 s steps, 40,000 s)",
             "paper001-stack"),
    Required("docs/paper003.md", "Paper's numbers vs measured", "paper003-numbers"),
    Required("docs/paper003.md", "Target tracking (leader only, `… test_p003_closed_loop.py tt`)", "paper003-tt"),
    Required("docs/paper004.md", "The paper's numbers against this implementation", "paper004-numbers"),
    Required("docs/performance.md", "Where the time of an in-process run goes", "performance-profile"),
    Required("docs/performance.md", "The real-time-factor curve", "rtf-curve"),
    Required("docs/performance.md", "Batch run ÷ vectorised floor, papers 000, 001, 003 and 004", "mission-floors"),
    Required("docs/performance.md", "Paper 000 in-process", "p000-speed"),
    Required("docs/reliability.md", "Lockstep does not depend on load", "reliability-lockstep"),
    Required("docs/camera-navigation.md", "The camera campaign against ideal sensing", "camera-campaign"),
    Required("docs/camera-navigation.md", "Where the rendered camera's error comes from: the layers on one seed",
             "camera-layers"),
    Required("docs/faults.md", "Example: paper 004 with a measurement dropout and a thruster failure",
             "faults-servicing"),
    Required("docs/faults.md", "Fault campaigns", "faults-campaign"),
    Required("docs/faults.md", "Hulls and contact", "faults-contacts"),
)

NOT_YET = tuple(r for r in REQUIRED if r.table is None)

# Sources whose claims are recorded with the default kernels only (a new module's, while its
# other-kernel runs are pending); tests/test_claims.py accepts them without `alt` and fails once
# one is measured, so the list only shrinks. `swarmhil claims --all --record` under
# OPENBLAS_CORETYPE=Sandybridge NPY_DISABLE_CPU_FEATURES=X86_V3 fills them.
ALT_PENDING: tuple[str, ...] = ()  # all measured (2026-12-03)

# Sources registered with their table before any value is recorded: the table renders "(not
# recorded)" until `swarmhil claims --study --only SOURCE --record` and `--write`.
# tests/test_claims.py accepts their claims without a value and fails once one is recorded, so the
# list only shrinks.
RECORD_PENDING: tuple[str, ...] = ()
