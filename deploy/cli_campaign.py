"""`swarmhil campaign SCENARIO --seeds N`: N seeded batch runs, one table, one report (issue 16).

    swarmhil campaign deploy/scenarios/sabatini-20.toml --seeds 20 [--first-seed 0] [--set SECTION.KEY=VALUE]...
        [--executor local|dask] [--scheduler tcp://HOST:8786] [--jobs J] [--duration S] [--out DIR]

Runs are in-process (deploy/launcher.py run_in_process; by default `--record truth`: the batch mode
of deploy/batch.py, the same flight-software and plant code and the same truth), seed s = first_seed .. first_seed + N - 1 (`[run].seed`: for a generated dispersion
it draws new initial conditions). Writes DIR/campaign.parquet and .csv (one row per run: seed, wall,
every scalar of its summary.json, metrics included), DIR/report.md and .html (mean and 95 %
confidence interval of dV, connectivity, closest approach). Re-running the same command on the
same DIR runs only the seeds without a result (deploy/campaign.py).
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import click


@click.command("campaign")
@click.argument("scenario", type=click.Path(exists=True, dir_okay=False))
@click.option("--seeds", "n_seeds", type=click.IntRange(min=1), required=True, help="Number of seeded runs.")
@click.option("--first-seed", type=int, default=0, show_default=True, help="Seed of the first run; then +1 each.")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Override a scenario field for every run (repeatable; value parsed as TOML).")
@click.option("--executor", type=click.Choice(["local", "dask"]), default="local", show_default=True,
              help="local: a process pool; dask: Dask distributed (a LocalCluster on 127.0.0.1, or --scheduler).")
@click.option("--scheduler", metavar="ADDRESS", help="Dask scheduler of a running cluster (tcp://host:8786); implies dask.")
@click.option("--jobs", type=click.IntRange(min=1), default=None, help="Runs at once on this machine (default: CPU count).")
@click.option("--duration", type=float, help="Simulated seconds (overrides [run].duration_s).")
@click.option("--out", "out", type=click.Path(file_okay=False), help="Campaign directory (default runs/campaign-<scenario>).")
@click.option("--metrics/--no-metrics", default=True, show_default=True,
              help="Compute each run's metrics (connectivity, closest approach) from its truth.")
@click.option("--keep-recordings/--no-keep-recordings", default=True, show_default=True,
              help="Keep each run's run.mcap (they are about 3 MB per simulated hour of sabatini-20).")
@click.option("--retry-failed", is_flag=True, help="Also run again the seeds whose earlier run failed.")
@click.option("--record", type=click.Choice(["truth", "all"]), default="truth", show_default=True,
              help="truth: record the truth and events only, and run the flight software of all spacecraft as "
                   "one batch where the scenario allows (same truth, several times faster); all: every message.")
@click.option("--faults", "faults", type=click.Path(exists=True, dir_okay=False),
              help="A faults file (docs/faults.md): each run flies a fault schedule drawn from it with its seed; the "
                   "report gives the fraction recovered per fault kind.")
@click.option("--baseline", is_flag=True,
              help="With --faults: also run the same seeds without faults (OUT/baseline) for the extra ΔV per run.")
def campaign(scenario: str, n_seeds: int, first_seed: int, sets: tuple[str, ...], executor: str, scheduler: str | None,
             jobs: int | None, duration: float | None, out: str | None, metrics: bool, keep_recordings: bool,
             retry_failed: bool, record: str, faults: str | None, baseline: bool) -> None:
    """Run SCENARIO with N seeds (batch mode) and write a Parquet/CSV table and a report."""
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.campaign import FaultDrawError, draw_faults, load_fault_draws, run_campaign, with_drawn_faults  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.scenario import ScenarioError, load_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    require("pyarrow", "swarmhil campaign (its Parquet table)")  # before any run, not after them
    if executor == "dask" or scheduler:
        require("dask.distributed", "--executor dask")

    if baseline and not faults:
        click.echo("error: --baseline needs --faults (it is the same campaign without them)", err=True)
        sys.exit(2)
    try:  # fail fast on a bad scenario, --set or faults file, before starting any worker
        sc = load_scenario(scenario, list(sets)).with_overrides(duration_s=duration)
        if faults:
            try:
                draws = load_fault_draws(faults, sc.ids)
                for seed in (first_seed, first_seed + n_seeds - 1):  # a drawn fault that does not fit the scenario
                    with_drawn_faults(sc, draw_faults(draws, sc.ids, seed))
            except FaultDrawError as exc:
                click.echo(f"error: {exc}", err=True)
                sys.exit(2)
    except ScenarioError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    if scheduler:
        executor = "dask"
    out_dir = Path(out) if out else Path("runs") / f"campaign-{sc.name}"
    seeds = list(range(first_seed, first_seed + n_seeds))
    t0 = time.monotonic()

    def show(row: dict) -> None:
        status = row.get("error") or f"total dV {row.get('delta_v_total_mps', float('nan')):.6f} m/s"
        click.echo(f"[{time.monotonic() - t0:7.1f} s] seed {row['seed']}: {status} ({row.get('wall_s', 0.0):.1f} s)")

    try:
        res = run_campaign(scenario, seeds, out_dir, sets=sets, duration_s=duration, executor=executor,
                           jobs=jobs or os.cpu_count() or 1, scheduler=scheduler, metrics=metrics,
                           keep_recording=keep_recordings, retry_failed=retry_failed, on_row=show, record=record,
                           faults=faults, baseline=baseline)
    except ValueError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    if res["skipped"]:
        click.echo(f"resumed: {len(res['skipped'])} seeds already done, {len(res['ran'])} run now")
    failed = [r for r in res["rows"] if r.get("status") != "ok"]
    click.echo(f"{len(res['rows'])} runs ({len(failed)} failed) in {res['wall_s']:.1f} s; wrote {res['table'][0]}, "
               f"{res['table'][1]}, {res['report'][0]}, {res['report'][1]}")
    if failed:
        sys.exit(1)


@click.command("campaign-compare")
@click.argument("base", type=click.Path(exists=True, file_okay=False))
@click.argument("others", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False))
@click.option("--label", "labels", multiple=True,
              help="Names of BASE and of each OTHER in the report, in that order (default base, other; with "
                   "several OTHERs their directory names).")
@click.option("--out", "out", type=click.Path(file_okay=False),
              help="Output directory (default OTHER/paired-<BASE name>; with several OTHERs BASE/compare).")
@click.option("--tolerance-pp", type=click.FloatRange(min=0.0), default=2.0, show_default=True,
              help="Per-step weak connectivity: the allowed |OTHER - BASE| in percentage points.")
@click.option("--window-h", type=click.FloatRange(min=0.0, min_open=True), default=2.0, show_default=True,
              help="Connectivity per time window of this many hours (from the recordings, when both were kept).")
@click.option("--at-least-pct", type=click.FloatRange(0.0, 100.0), default=97.0, show_default=True,
              help="The headline counts the seeds whose per-step connectivity under OTHER is at least this [%].")
def campaign_compare(base: str, others: tuple[str, ...], labels: tuple[str, ...], out: str | None, tolerance_pp: float,
                     window_h: float, at_least_pct: float) -> None:
    """Compare campaigns seed by seed against BASE (same seeds, same initial conditions): the
    difference in connectivity, the dV ratio, closest approach, with 95 % confidence intervals over
    the seeds; the seeds that split under OTHER only (and under BASE only); and a headline over the
    seeds where BASE stays whole. Writes OUT/compare.json and OUT/compare.md beside the paired tables."""
    from swarmhil.deploy.campaign_compare import WCF, CompareError, write_compare  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if labels and len(labels) != len(others) + 1:
        click.echo(f"error: --label must be given {len(others) + 1} times (BASE, then each OTHER) or not at all",
                   err=True)
        sys.exit(2)
    if out:
        out_dir = Path(out)
    else:
        out_dir = Path(others[0]) / f"paired-{Path(base).name}" if len(others) == 1 else Path(base) / "compare"
    try:
        res = write_compare(base, others, out_dir, labels or None, tolerance_pp, window_h * 3600.0, at_least_pct)
    except CompareError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    lb = res["compare"]["base"]["label"]
    for lab, one in res["paired"].items():
        st = one["stats"]
        s = st["metrics"][WCF]
        agg = res["compare"]["others"][lab]
        h = agg["headline"]
        ci = "" if s["ci95_low"] is None else f", 95 % CI [{s['ci95_low']:+.2f}, {s['ci95_high']:+.2f}]"
        hc = h["other_connectivity_pct"]
        head = ("no seed" if not h["n"] else
                f"mean {hc['mean']:.2f} %, min {hc['min']:.2f} %, {h['other_at_least']} of {h['n']} >= {at_least_pct:g} %")
        click.echo(f"{'' if len(others) == 1 else lab + ': '}{st['seeds']} paired seeds (same initial state: "
                   f"{st['same_initial_state']}); per-step weak connectivity difference {s['mean']:+.2f} pp{ci}; "
                   f"{st['seeds_within']} of {st['seeds']} within {tolerance_pp:g} pp; split only under {lab}: "
                   f"{agg['split_other_only']['n']}, only under {lb}: {agg['split_base_only']['n']}; where {lb} stays "
                   f"whole ({h['n']} seeds): {head}; "
                   f"wrote {', '.join(str(p) for p in one['paths'])}")
    click.echo(f"wrote {', '.join(str(p) for p in res['paths'])}")
