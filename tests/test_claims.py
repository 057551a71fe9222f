"""The claims registry (claims/, docs/claims.md): the docs' tables are what the registry renders,
every number in them is a claim, the quick claims hold here (`make test`), the others in the
system tests (`swarmhil claims --all`)."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from conftest import ROOT


def _reg():  # type: ignore[no-untyped-def]
    from swarmhil.claims.registry import registry

    return registry()


def test_every_claim_has_a_recorded_value_and_the_other_kernel_sets():
    from swarmhil.claims.coverage import ALT_PENDING, RECORD_PENDING

    reg = _reg()
    missing = [c.id for c in reg.claims.values() if c.value is None and c.source not in RECORD_PENDING]
    assert not missing, f"not recorded (swarmhil claims --all --record): {missing}"
    recorded = {c.source for c in reg.claims.values() if c.value is not None}
    assert not recorded & set(RECORD_PENDING), "recorded now: take it out of claims/coverage.py RECORD_PENDING"
    assert all(reg.sources[s].tier == "study" for s in RECORD_PENDING), "only a study source may wait for its values"

    no_alt = [c.id for c in reg.claims.values()
              if c.alt is None and reg.tier(c) in ("quick", "all") and c.source not in ALT_PENDING]
    assert not no_alt, f"not measured under the other kernel set (docs/claims.md): {no_alt}"
    measured = {c.source for c in reg.claims.values() if c.alt is not None}
    assert not measured & set(ALT_PENDING), "measured now: take it out of claims/coverage.py ALT_PENDING"


def _numeric(c) -> bool:  # type: ignore[no-untyped-def]
    return isinstance(c.value, (int, float)) and not isinstance(c.value, bool) and not c.tol.shape_only


def test_every_checked_claim_can_fail_and_its_measured_samples_fit_under_the_cap():
    """A checked number's band stops short of zero unless it is a residual, and stops at the cap:
    a measured value at a tenth of the recorded one fails (docs/claims.md "The cap"). The recorded
    samples (alt, nudged runs, other processors) lie in the band: the band is built from them, but
    the cap and explicit tolerances are not, so a spread too wide for a claim that can fail fails here."""
    from swarmhil.claims.model import CAP

    reg = _reg()
    checked = [c for c in reg.claims.values() if _numeric(c) and reg.tier(c) != "bench"]
    assert len(checked) > 1000
    zero = [c.id for c in checked if not c.residual and c.value != 0 and c.tol.holds(0.0, c.value)]
    assert not zero, f"a measured 0 would pass: {zero}"
    tenth = [c.id for c in checked if not c.residual and c.value != 0 and c.tol.holds((1 - CAP) * 0.99 * c.value, c.value)]
    assert not tenth, f"beyond the cap: {tenth}"
    outside = [(c.id, v) for c in checked for v in ((c.alt,) if c.alt is not None else ()) + c.nudged + c.machines
               if not c.tol.holds(v, c.value)]
    assert not outside, f"a recorded sample outside its claim's band: {outside}"
    # the residuals are the few differences meant to be about zero, each bounded
    residuals = sorted(c.id for c in checked if c.residual)
    assert residuals and all(c.tol.band(float(c.value))[1] <= 1e-2 for c in checked if c.residual), residuals


def test_a_band_reaching_zero_is_refused_unless_the_claim_is_a_residual():
    """The registry refuses a tolerance band that reaches zero for a non-zero value (paper 004's
    errors after 200 s had relative floors of 93 % and 125 % plus 1.5 x the nudged runs' range:
    2.82 m ± 4.16 m + 125 % passed anything from 0 to 10.5 m)."""
    import dataclasses

    from swarmhil.claims.model import Claim, Tol, band_reaches_zero, resolve_tol
    from swarmhil.claims.registry import refuse_band_reaching_zero

    wide = Claim("t.e-max", "s", lambda s: s["v"], Tol(abs=4.16, rel=1.25), "an error [m]", "s3", value=2.82)
    assert band_reaches_zero(wide)
    with pytest.raises(ValueError, match="t.e-max.*reaches zero"):
        refuse_band_reaching_zero(wide)
    refuse_band_reaching_zero(dataclasses.replace(wide, residual=True))  # a residual may reach zero
    refuse_band_reaching_zero(dataclasses.replace(wide, value=0.0))      # so may a value of zero
    # paper 004's case as recorded: the band from its own ensemble no longer reaches zero
    reg = _reg()
    e = reg.claims["p004.paper.e-max"]
    lo, hi = e.tol.band(float(e.value))
    assert 0.0 < lo < min((e.value, e.alt, *e.nudged)) and hi > max((e.value, e.alt, *e.nudged)), (lo, hi)
    assert not e.tol.holds(0.3, e.value) and not e.tol.holds(10.0, e.value)
    # the cap: a two-sample spread wider than the value is clipped at a tenth of it
    t = resolve_tol(Tol(auto=True), 0.06, 0.09, ".2f")
    assert t.band(0.06) == pytest.approx((0.006, 0.15)) and not t.holds(0.0, 0.06)
    assert resolve_tol(Tol(auto=True), 0.06, 0.09, ".2f", residual=True).holds(0.0, 0.06)


def test_nudged_runs_are_recorded_and_make_an_envelope():
    """A source that declares one-ulp nudged runs has them recorded for each numeric claim; its
    claims' bands are the envelope of value, alt and the nudges, widened by half their range each
    side (docs/claims.md "One-ulp nudges"), not a band around the recorded value alone."""
    from swarmhil.claims.model import Tol, resolve_tol

    reg = _reg()
    declared = [c for c in reg.claims.values() if reg.sources[c.source].nudged is not None
                and isinstance(c.value, float)]
    assert declared, "no source declares nudged runs (paper 004's do)"
    missing = [c.id for c in declared if len(c.nudged) < 8]
    assert not missing, f"nudged runs not recorded (swarmhil claims --all --record --nudges 8): {missing}"
    auto = Tol(auto=True)
    # the rule: an asymmetric spread gives an asymmetric band, a flat one half the printed digit
    assert resolve_tol(auto, 100.0, 100.0, ".3g", nudged=(90.0, 130.0)).band(100.0) == (70.0, 150.0)
    assert resolve_tol(auto, 100.0, 101.0, ".3g", nudged=(100.0, 100.0)).band(100.0) == (99.5, 101.5)
    assert resolve_tol(auto, 100.0, 101.0, ".3g").band(100.0) == (97.0, 103.0)  # two samples: 3 x their difference
    assert resolve_tol(auto, 100.0, 100.0, ".3g").band(100.0) == (99.5, 100.5)


def test_paper000_stack_sources_compute_their_claims_from_a_short_run():
    """The study-tier stack sources of paper 000 (claims/paper000_stack.py, paper000_repro.py) on a
    2 s capture-10 run: every claim computes a number from what `swarmhil report` wrote, so a renamed
    metric fails here and not only in a study run."""
    import math

    from swarmhil.claims.paper000_repro import across_seeds
    from swarmhil.claims.paper000_stack import stack_run

    reg = _reg()
    res = stack_run((), duration_s=2.0)
    assert res["n_agents"] == 10 and res["state_tx"] >= 0
    counted = {**res, "state_tx": max(res["state_tx"], 1), "state_tx_bytes": max(res["state_tx_bytes"], 84),
               "all_tx_bytes": max(res["all_tx_bytes"], 84)}
    seeds = across_seeds(lambda name: counted)  # no packet before the first chase (21.7 s): counts of one
    derived = {"p000.stack.saving": {k: 1.0 for k in ("state_tx_bytes", "state_rx_bytes", "all_tx_bytes",
                                                       "all_rx_bytes")}, "p000.repro.seeds": seeds}
    claims = [c for c in reg.claims.values() if c.source.startswith(("p000.stack", "p000.repro"))]
    assert len(claims) > 90
    for c in claims:
        v = c.compute(derived.get(c.source, res))
        assert isinstance(v, (int, float)) and not math.isnan(float(v)) or c.id.endswith(
            ("axes-worst", "centre-max", "settle-max", "r1hz-std", "revery-std")), (c.id, v)


def test_docs_tables_are_what_the_registry_renders():
    from swarmhil.claims.render import doc_drift

    reg = _reg()
    assert doc_drift(reg.tables, reg.claims) == []


def test_every_number_of_a_claims_table_is_a_claim():
    """Numbers in the measured columns come from placeholders, except declared parameters; each
    claim is shown, in a table or after a number of the prose (`<!-- claim:ID -->`); each table row
    has a computed verdict where the table has a verdict column."""
    from swarmhil.claims import prose
    from swarmhil.claims.model import check_row_numbers

    reg = _reg()
    shown: set[str] = {r.id for p in prose.docs() for r in prose.scan(p.read_text(), p.name)[1]}
    for t in reg.tables.values():
        shown |= set(t.placeholders())
        for i, row in enumerate(t.rows):
            assert check_row_numbers(row, t.measured) == [], f"{t.id} row {i + 1}: a typed number"
            assert len(row.cells) + (t.verdict_col is not None) == len(t.header), f"{t.id} row {i + 1}"
            if t.verdict_col is not None:
                assert row.verdict is not None, f"{t.id} row {i + 1}: verdict typed, not computed"
    assert set(reg.claims) - shown == set()


def test_typed_numbers_are_caught():
    from swarmhil.claims.model import Row, check_row_numbers, literal_numbers

    assert literal_numbers("min {p.x} m at 20 h, sc07 (Fig. 10), mm/s^2") == ["20"]
    assert check_row_numbers(Row(("a", "min {p.x} m, 3.45 h")), (1,)) == ["3.45"]
    assert check_row_numbers(Row(("a", "below 5 m after {p.x} h"), params=("5",)), (1,)) == []


def test_marked_tables_are_rewritten_and_nothing_else():
    from swarmhil.claims.model import Claim, Row, Table, Tol
    from swarmhil.claims.render import blocks, render_table, rewrite

    c = Claim("t.v", "s", lambda s: s["v"], Tol(abs=0.1), "a value", ".2f", value=2.441)
    t = Table("t-x", "doc.md", ("claim", "measured", "verdict"), (
        Row(("dV", "{t.v} m/s"), lambda v: "reproduced" if v["t.v"] > 2 else "not reproduced"),), (1,), 2)
    doc = "intro 1.0\n<!-- claims:t-x -->\n| old |\n<!-- /claims -->\nafter 3.0\n"
    new = rewrite(doc, {"t-x": t}, {"t.v": c})
    assert new.startswith("intro 1.0\n<!-- claims:t-x -->\n| claim | measured | verdict |")
    assert "| dV | 2.44 m/s | reproduced |" in new and new.endswith("<!-- /claims -->\nafter 3.0\n")
    assert blocks(new)["t-x"] == render_table(t, {"t.v": c})
    assert "| dV | 1.50 m/s | not reproduced |" in render_table(t, {"t.v": c}, {"t.v": 1.5})  # verdict follows
    assert Tol(abs=0.1).holds(2.5, 2.441) and not Tol(abs=0.01).holds(2.5, 2.441)
    assert Tol(rel=0.05).holds(2.5, 2.441) and not Tol().holds(None, 2.441)  # type: ignore[arg-type]
    assert Tol().holds(("sc07",), ("sc07",)) and not Tol(abs=1.0).holds(("sc10",), ("sc07",))


def test_every_required_table_is_covered_or_listed_as_not_yet():
    from swarmhil.claims.coverage import NOT_YET, REQUIRED
    from swarmhil.claims.render import blocks

    reg = _reg()
    for r in REQUIRED:
        text = (ROOT / r.doc).read_text()
        assert re.search(rf"^#+ {re.escape(r.heading)}$", text, re.M), f"{r.doc}: no heading {r.heading!r}"
        if r.table is None:
            assert r.why_not, r
        else:
            assert r.table in reg.tables and r.table in blocks(text), r
    # the allow-list only shrinks: a table that got a marker leaves it; it is empty now (issue 24)
    assert all(r.table is None for r in NOT_YET)
    assert not NOT_YET, [f"{r.doc}: {r.heading}" for r in NOT_YET]
    covered = {r.table for r in REQUIRED if r.table}
    assert covered == set(reg.tables), "a claims table not in claims/coverage.py REQUIRED"


def test_quick_claims_hold_and_keep_their_verdicts():
    """`swarmhil claims --quick`, in-process: e.g. paper 002's 24 h sabatini-20 run in batch mode."""
    from swarmhil.claims.runner import SourceCache, rerun, verdict_changes

    reg = _reg()
    outs = rerun(reg.select(("quick",)), SourceCache(reg.sources))
    assert outs, "no quick claims"
    bad = [f"{o.claim.id}: {o.measured} vs {o.claim.value} ({o.claim.tol.describe()}) {o.error}"
           for o in outs if not o.ok]
    assert bad == []
    assert verdict_changes(reg.tables, reg.claims, {o.claim.id: o.measured for o in outs}) == []


@pytest.mark.system
@pytest.mark.timeout(2400)  # ~10-12 min on a quiet machine; pyproject's 600 s default would stop it
def test_all_claims_hold():
    """`swarmhil claims --all --untested --jobs 2`: the minutes-long sources (paper 002's noise runs,
    ...), two at a time; the runs a CI test makes itself are checked by that test (`checked_by`)."""
    res = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "claims", "--all", "--untested", "--jobs", "2"], cwd=ROOT,
                         capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]


def _test_function(node: str):  # type: ignore[no-untyped-def]
    import ast

    path, name = node.split("::")
    tree = ast.parse((ROOT / path).read_text())
    return next((f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name == name), None)


def test_a_source_checked_by_a_test_is_checked_there():
    """`--untested` skips a source only because the test it names makes the run and calls
    `claim_failures` on it; that test is not a study test (CI runs it)."""
    import ast

    reg = _reg()
    checked = [s for s in reg.sources.values() if s.checked_by]
    assert len(checked) >= 10
    for s in checked:
        fn = _test_function(s.checked_by)
        assert fn is not None, f"{s.name}: no test {s.checked_by}"
        calls = {c.func.id for c in ast.walk(fn) if isinstance(c, ast.Call) and isinstance(c.func, ast.Name)}
        assert "claim_failures" in calls, f"{s.checked_by} does not check {s.name}'s claims"
        marks = [ast.unparse(d) for d in fn.decorator_list]
        assert "pytest.mark.study" not in marks, f"{s.checked_by} is a study test: CI does not run it"


def test_claim_failures_name_the_claims_a_run_misses():
    """Positive control of claims/check.py: a leader-only run that missed its row fails by claim."""
    from types import SimpleNamespace

    import numpy as np

    from swarmhil.claims.check import claim_failures

    reg = _reg()
    want = {k: reg.claims[f"p003.tt-g1.{k}"].value for k in ("tt-end", "ratio", "first10", "peak")}
    t = np.arange(0.0, 300.05, 0.1)
    err = np.full((t.size, 3), 20.0)
    err[t >= want["first10"], :] = want["tt-end"]  # the right TT error and time, the wrong funnel ratio and thrust
    run = SimpleNamespace(t_s=t, tt_err_m=err, funnel_m=np.full(t.size, 1000.0), leader_thrust_n=np.full(t.size, 1.0))
    bad = claim_failures("p003.tt-g1", run)
    assert [b.split(":")[0] for b in bad] == ["p003.tt-g1.ratio", "p003.tt-g1.peak"], bad


def test_sources_run_in_worker_processes_once():
    """`--jobs 2`: the sources are computed in two worker processes, with the same results."""
    from swarmhil.claims.runner import SourceCache

    reg = _reg()
    names = [n for n in reg.sources if n.startswith("p002.init-")][:3]
    assert len(names) == 3
    par = SourceCache(reg.sources)
    par.prefetch(names, 2)
    assert set(par.mem) == set(names) and set(par.wall_s) == set(names)
    seq = SourceCache(reg.sources)
    assert all(seq.get(n) == par.mem[n] for n in names)


def test_the_release_study_builds_and_its_recorded_rows_are_the_docs():
    """claims/paper001_study.py is not registered yet (claims/coverage.py NOT_YET: its 30 runs are
    not all recorded): it merges with the registry (no id twice, no dangling source or claim,
    every claim shown, no typed number), and each release already in claims/recorded.json renders
    the very row docs/paper001.md shows, so recording the rest is all that registering takes."""
    import dataclasses

    from swarmhil.claims import paper001_study as study
    from swarmhil.claims.model import PLACEHOLDER, check_row_numbers
    from swarmhil.claims.registry import modules, read_recorded
    from swarmhil.claims.render import fill

    reg = _reg()
    names = [s.name for s in study.SOURCES]
    ids = [c.id for c in study.CLAIMS]
    if study in modules():  # registered: the registry itself has refused duplicates and dangling names
        assert set(names) <= set(reg.sources) and set(ids) <= set(reg.claims)
    else:
        assert len(set(names)) == len(names) and not set(names) & set(reg.sources)
        assert len(set(ids)) == len(ids) and not set(ids) & set(reg.claims)
    sources = set(reg.sources) | set(names)
    assert all(set(s.uses) <= sources for s in study.SOURCES)
    assert all(c.source in sources for c in study.CLAIMS)
    rec = read_recorded()
    claims = dict(reg.claims)
    for c in study.CLAIMS:
        v = rec.get(c.id, {}).get("value")
        claims[c.id] = dataclasses.replace(c, value=tuple(v) if isinstance(v, list) else v)
    shown: set[str] = set()
    doc = (ROOT / study.DOC).read_text()
    n_rows = 0
    for t in study.TABLES:
        assert set(t.placeholders()) <= set(claims), t.id
        shown |= set(t.placeholders())
        for row in t.rows:
            assert check_row_numbers(row, t.measured) == [], f"{t.id}: a typed number"
            used = [m.group(1) for cell in row.cells for m in PLACEHOLDER.finditer(cell)]
            if t.id != "paper001-verdicts" and all(claims[k].value is not None for k in used):
                line = "| " + " | ".join(fill(c, claims, {}) for c in row.cells) + " |"
                assert line in doc, f"{t.id}: {line}"
                n_rows += 1
    assert set(ids) <= shown
    assert n_rows >= 5  # paper oct, 0, 1, 2 and ae 3 recorded on 2026-12-03


def test_every_verdict_reads_only_claims_and_a_missing_id_is_raised_not_hidden():
    """Each table's verdicts computed from the recorded values read only ids of the registry (a
    verdict reading another id was shown as "(not recorded)" before); the renderer raises on one."""
    from swarmhil.claims.registry import registry
    from swarmhil.claims.render import _verdict, verdicts

    reg = registry()
    for table in reg.tables.values():
        verdicts(table, reg.claims)  # raises KeyError naming the id if a verdict reads a non-claim
    with pytest.raises(KeyError, match="p000.nonexistent.*not a claim"):
        _verdict(lambda v: v["p000.nonexistent"], {})
    assert _verdict(lambda v: str(float(v["x"])), {"x": None}) == "(not recorded)"


def test_paper002_threshold_and_spacing_verdicts_judge_what_their_rows_claim():
    from swarmhil.claims.paper002 import _v_ca_vis, _v_integrity

    base = {"p002.split30": 3, "p002.split35": 1}
    assert _v_integrity({**base, "p002.intact10": 0, "p002.intact20": 0}).startswith("not reproduced: integrity already lost at 10 %")
    assert _v_integrity({**base, "p002.intact10": 1, "p002.intact20": 2}).startswith("partly")
    assert _v_ca_vis({"p002.ca-vis": 68.2, "p002.ca-vis-steady": 124.6}).startswith("partly")
    assert _v_ca_vis({"p002.ca-vis": 68.2, "p002.ca-vis-steady": 90.0}) == "not reproduced: below d_min, above d_min_trans"
    assert _v_ca_vis({"p002.ca-vis": 104.0, "p002.ca-vis-steady": 124.6}).startswith("reproduced")


def test_list_and_failures_point_at_the_row_that_shows_the_claim():
    """`--list` and the FAIL / VERDICT lines name doc:line of the row itself (they named the line
    above it: the separator for the first row)."""
    from swarmhil.claims.render import doc_line, render_table
    from swarmhil.claims.runner import locate

    reg = _reg()
    texts: dict[str, list[str]] = {}
    for t in reg.tables.values():
        lines = texts.setdefault(t.doc, (ROOT / t.doc).read_text().splitlines())
        rows = render_table(t, reg.claims).splitlines()[2:]
        for i, row in enumerate(rows):
            n = doc_line(t, i)
            assert n is not None and lines[n - 1] == row, f"{t.doc}:{n} is not row {i + 1} of {t.id}"
    where = locate(reg.claims, reg.tables)
    doc, n = where["p004.paper.e-max"].split(":")
    assert "paper's case" in texts[doc][int(n) - 1]
    out = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "claims", "--list"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120).stdout
    line = next(x for x in out.splitlines() if x.startswith("p004.paper.e-max\t"))
    assert line.split("\t")[3] == where["p004.paper.e-max"]


def test_the_floor_against_the_truth_is_a_checked_claim():
    """docs/performance.md's floor-vs-truth column states correctness, not a timing: its claims are
    checked (tier `all`, residuals with a stated bound), not presence-only bench figures."""
    reg = _reg()
    col = [c for c in reg.claims.values() if c.id.startswith("floors.") and c.id.endswith(("dv_diff", "pos_diff"))]
    assert len(col) == 10
    for c in col:
        assert reg.tier(c) == "all" and not c.tol.shape_only and c.residual, c.id
        assert c.tol.holds(c.value, c.value) and not c.tol.holds(1e-3, c.value), c.id  # a wrong floor fails
        assert c.alt is not None and c.tol.holds(c.alt, c.value), c.id
