"""`swarmhil report-bandwidth RUN_DIR [--compare RUN_DIR_B]`: the link bandwidth report (issue 5).

The main report can include the same content through `dashboards.bandwidth.page.write_bandwidth_report`
(or `bandwidth_section` for an HTML section).
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click


@click.command("report-bandwidth")
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False))
@click.option("--compare", "compare", type=click.Path(exists=True, file_okay=False),
              help="A second run directory: both runs side by side (B / A ratios).")
@click.option("--out", "out", type=click.Path(dir_okay=False),
              help="Output HTML (default RUN_DIR/report/bandwidth.html, or bandwidth_compare.html with --compare).")
def report_bandwidth(run_dir: str, compare: str | None, out: str | None) -> None:
    """Bytes and messages per agent and per link, drops by cause, totals: from RUN_DIR/run.mcap alone,
    checked against the channel's own counters (exit code 1 when they disagree). A run without a
    link (no [link] in its scenario) gets an empty report that says so, exit code 0."""
    from swarmhil.dashboards.bandwidth import accounting, page, read  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import check_run_dir  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    for r in [run_dir, compare] if compare else [run_dir]:
        check_run_dir(r)
    runs = {r: read.read_link_traffic(r) for r in ([run_dir, compare] if compare else [run_dir])}
    if not compare and not runs[run_dir].has_link:
        path = _write_no_link_report(runs[run_dir], Path(out) if out else Path(run_dir) / "report" / "bandwidth.html")
        click.echo(f"{runs[run_dir].run}: no inter-satellite link in this run ([link] absent or disabled in its "
                   f"scenario): nothing to count; wrote an empty report {path}")
        return
    if compare:
        path = page.write_bandwidth_comparison(runs[run_dir], runs[compare],
                                          Path(out) if out else Path(run_dir) / "report" / "bandwidth_compare.html")
    else:
        path = page.write_bandwidth_report(run_dir, out, traffic=runs[run_dir])
    click.echo(f"wrote {path}")
    bad = False
    for r, lt in runs.items():
        if not lt.has_link:
            click.echo(f"{lt.run}: no inter-satellite link in this run: counted as zero traffic")
            continue
        checks = accounting.consistency(lt)
        for name, rec, stats, summ, ok in checks:
            if not ok:
                bad = True
                click.echo(f"{r}: {name}: recording {rec}, LinkStats {stats}, summary.json {summ}: DISAGREE", err=True)
        rows = {c[0]: c for c in checks}
        click.echo(f"{lt.run}: {rows['tx_messages'][1]} transmissions ({rows['tx_wire_bytes'][1]} B with overhead), "
                   f"{rows['rx_messages'][1]} deliveries ({rows['rx_wire_bytes'][1]} B), drops range/occulted/lost/queue "
                   f"{rows['dropped_range'][2]}/{rows['dropped_occulted'][2]}/{rows['dropped_lost'][2]}/{rows['dropped_queue'][2]}, "
                   f"rejected {rows['rejected_packets'][1]}, beyond range {lt.beyond_range}")
    if bad:
        sys.exit(1)


def _write_no_link_report(lt: Any, path: Path) -> Path:
    """The bandwidth page of a run without a link: it says so, and has no table or figure."""
    import html

    from swarmhil.dashboards.bandwidth.page import write_page  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    path.parent.mkdir(parents=True, exist_ok=True)
    return write_page(f"swarmhil bandwidth: {lt.run}",
                 f"<p>Run <code>{html.escape(lt.run)}</code> has no inter-satellite link (no <code>[link]</code> "
                 "table in its scenario, or it is disabled): no transmission, delivery or link counter was "
                 "recorded, so there is nothing to count.</p>", path)
