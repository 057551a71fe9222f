"""`swarmhil claims`: rerun the docs' numbers and check or rewrite the tables the docs include."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import click


def _writable(_ctx: click.Context, _param: click.Parameter, value: str | None) -> str | None:
    """--json: refused up front (exit 2) when its directory cannot be written."""
    if value is not None:
        parent = Path(value).resolve().parent
        if not parent.is_dir() or not os.access(parent, os.W_OK):
            raise click.BadParameter(f"{value}: cannot be written (no writable directory {parent})")
    return value


def _tiers(quick: bool, all_: bool, study: bool, bench: bool) -> tuple[str, ...]:
    if all_:
        return ("quick", "all")
    chosen = tuple(t for t, on in (("quick", quick), ("study", study), ("bench", bench)) if on)
    return chosen or ("quick",)


def _prose(claims: dict, lower: bool) -> int:
    """`swarmhil claims --prose`: one line per unmarked measured-looking number (`doc:line: text`), one
    per stale claim reference and per doc above (or below) its baseline; the exit code."""
    from swarmhil.claims import prose as p

    found = p.unmarked()
    for hits in found.values():
        for h in hits:
            click.echo(str(h))
    if lower:
        new = p.lower_baseline(found)
        click.echo(f"baseline: {sum(new.values())} numbers in {len(new)} docs", err=True)
    errors = p.ref_errors(claims) + p.heading_marks() + p.baseline_errors(found, p.baseline())
    for e in errors:
        click.echo(f"PROSE {e}")
    per_doc = ", ".join(f"{d} {len(h)}" for d, h in found.items())
    click.echo(f"{sum(map(len, found.values()))} unmarked numbers in prose ({per_doc or 'none'}); "
               f"{len(errors)} failures", err=True)
    return 1 if errors else 0


@click.command("claims")
@click.option("--quick", "quick", is_flag=True, help="The claims that take seconds (the default; run by `make test`).")
@click.option("--all", "all_", is_flag=True, help="Quick and minutes-long claims (the system tests).")
@click.option("--study", is_flag=True, help="The hours-long claims (paper studies; not run by CI).")
@click.option("--bench", is_flag=True, help="Timings on this machine: checked for presence and shape only.")
@click.option("--write", is_flag=True, help="Rewrite the docs' marked tables from the registry (no run).")
@click.option("--check-docs", is_flag=True, help="Only check that the docs' marked tables are what the registry renders.")
@click.option("--record", "record_", is_flag=True,
              help="Store the measured values in claims/recorded.json (as `alt` under another kernel set).")
@click.option("--nudges", default=0, type=click.IntRange(0, 64), metavar="N",
              help="With --record (default kernels): also run N one-ulp nudged runs of the sources that have "
                   "them and store their values (`nudged`), which widen those claims' tolerances.")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), callback=_writable,
              help="Write the outcomes as JSON here.")
@click.option("--cache", type=click.Path(file_okay=False),
              help="Keep each source's result here (per kernel set) and reuse it; not for checking.")
@click.option("--untested", is_flag=True,
              help="Skip the sources whose run a CI test makes and checks itself (claims/check.py; CI's --all).")
@click.option("--only", default="", metavar="PREFIX",
              help="Only the claims whose source name starts with PREFIX (e.g. p003.), to measure one module.")
@click.option("--jobs", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Run this many sources at a time, each in its own process (CI: 2, the machine's cores).")
@click.option("--list", "list_", is_flag=True, help="List the claims (id, tier, tolerance, doc line) and exit.")
@click.option("--prose", is_flag=True,
              help="Only list the measured-looking numbers of the docs' prose that are neither claims nor marked "
                   "(claims/prose.py); exit 1 when a doc holds more than its baseline or a claim reference is stale.")
@click.option("--lower-baseline", is_flag=True,
              help="With --prose: lower each doc's baseline (claims/prose_baseline.json) to its count now; never raises.")
def claims(quick: bool, all_: bool, study: bool, bench: bool, write: bool, check_docs: bool, record_: bool,
           nudges: int, json_out: str | None, cache: str | None, untested: bool, only: str, jobs: int, list_: bool,
           prose: bool, lower_baseline: bool) -> None:
    """Rerun the numbers the docs state (claims/, docs/claims.md) and compare with the recorded ones.

    Exit 0 when every selected claim holds within its tolerance, every verdict computed from the
    values measured now is the doc's, and the docs' marked tables are what the registry renders."""
    from swarmhil.claims.registry import record, registry
    from swarmhil.claims.render import doc_drift, write_docs
    from swarmhil.claims.runner import SourceCache, kernel_set, locate, nudged_values, rerun, verdict_changes

    from swarmhil.claims import prose as prose_mod

    if lower_baseline and not prose:
        raise click.UsageError("--lower-baseline goes with --prose")
    reg = registry()
    if prose:
        sys.exit(_prose(reg.claims, lower_baseline))
    where = locate(reg.claims, reg.tables)
    if list_:
        for c in reg.claims.values():
            click.echo(f"{c.id}\t{reg.tier(c)}\t{c.tol.describe()}\t{where.get(c.id, '-')}\t{c.what}")
        return
    if write:
        for doc in sorted(set(write_docs(reg.tables, reg.claims)) | set(prose_mod.write_refs(reg.claims))):
            click.echo(f"rewrote {doc}")
        return
    drift = doc_drift(reg.tables, reg.claims) + prose_mod.ref_errors(reg.claims)
    for d in drift:
        click.echo(f"DOC  {d}")
    if check_docs:
        sys.exit(1 if drift else 0)
    tiers = _tiers(quick, all_, study, bench)
    kset = kernel_set()
    if nudges and not (record_ and kset == "default"):
        raise click.UsageError("--nudges records the nudged runs: use it with --record, under the default kernels")
    click.echo(f"claims: tiers {', '.join(tiers)}; kernels {kset}", err=True)
    sc = SourceCache(reg.sources, Path(cache) if cache else None, lambda s: click.echo(s, err=True))
    chosen = [c for c in reg.select(tiers) if c.source.startswith(only)
              and not (untested and reg.sources[c.source].checked_by)]
    sc.prefetch(dict.fromkeys(c.source for c in chosen), jobs)
    outs = rerun(chosen, sc)
    measured = {o.claim.id: o.measured for o in outs if o.measured is not None}
    bad = 0
    for o in outs:
        c = o.claim
        flag = "ok  " if o.ok else "FAIL"
        bad += not o.ok
        got = o.error or c.render(o.measured, None)
        click.echo(f"{flag} {c.id}: {got} (recorded {c.render()}, {c.tol.describe()}; alt {c.render(c.alt) if c.alt is not None else '-'}) "
                   f"{where.get(c.id, '')}")
    changes = verdict_changes(reg.tables, reg.claims, measured)
    for ch in changes:
        click.echo(f"VERDICT {ch}")
    if json_out:
        Path(json_out).write_text(json.dumps({"kernels": kset, "source_wall_s": sc.wall_s, "source_cpu_s": sc.cpu_s, "claims": {
            o.claim.id: {"measured": o.measured, "recorded": o.claim.value, "ok": o.ok, "error": o.error}
            for o in outs}}, indent=1, default=list))
    if record_:
        record(measured, "value" if kset == "default" else "alt", kset)
        click.echo(f"recorded {len(measured)} values ({'value' if kset == 'default' else 'alt'})", err=True)
        if nudges:
            spread = nudged_values(chosen, reg.sources, nudges, jobs, lambda s: click.echo(s, err=True))
            record(spread, "nudged", kset)
            click.echo(f"recorded {nudges} nudged values of {len(spread)} claims", err=True)
        return
    n = len(outs)
    click.echo(f"{n - bad} of {n} claims hold; {len(changes)} verdict changes; {len(drift)} doc tables drifted",
               err=True)
    sys.exit(1 if bad or changes or drift else 0)
