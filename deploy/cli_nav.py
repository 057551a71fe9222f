"""`swarmhil report-nav RUN_DIR [RUN_DIR ...] --out DIR` (issue 4).

For each run: the navigation error of every track against truth (RUN_DIR/navreport/index.html,
nav_summary.json, nav_table.md, PNGs), the splits of the swarm with the visibility edges lost and
what each side's navigation believed about them, and each navigation layer against truth per step
(issue 36: nav_splits.json / .md, nav_steps.json; dashboards/navreport/diagnosis.py); the splits of
each run are printed. Then one comparison table over the runs, the first being the
dV reference (DIR/comparison.md, .json, .html): total dV, weak connectivity, separations, closest
approach, navigation error. Everything is computed from each RUN_DIR/run.mcap alone
(dashboards/navreport/; swarm metrics from dashboards/metrics.py).
"""
from __future__ import annotations

from pathlib import Path

import click


@click.command("report-nav")
@click.argument("run_dirs", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False))
@click.option("--out", "out", required=True, type=click.Path(file_okay=False), help="Directory of the comparison table.")
@click.option("--label", "labels", multiple=True, help="Row label per RUN_DIR, in order (default: scenario name).")
def report_nav(run_dirs: tuple[str, ...], out: str, labels: tuple[str, ...]) -> None:
    """Navigation error against truth per run, and a comparison table across the runs."""
    from swarmhil.dashboards.navreport.page import splits_text, write_comparison, write_nav_report  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import check_run_dir  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    require("matplotlib", "swarmhil report-nav (its figures)")
    for d in run_dirs:
        check_run_dir(d)

    if labels and len(labels) != len(run_dirs):
        raise click.BadParameter(f"{len(labels)} --label for {len(run_dirs)} RUN_DIRs", param_hint="--label")
    try:
        for d in run_dirs:
            page = write_nav_report(d)
            click.echo(splits_text(page.parent), nl=False)
            click.echo(f"wrote {page}")
        table = write_comparison(run_dirs, out, list(labels) or None)
    except (OSError, ValueError) as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(Path(table).read_text(), nl=False)
    click.echo(f"wrote {table}")
