"""`swarmhil scale SCENARIO COUNT`: the scenario of a drawn swarm at COUNT spacecraft, at the paper's
density (deploy/scale.py, docs/scaling.md)."""
from __future__ import annotations

import sys

import click


@click.command("scale")
@click.argument("scenario", type=click.Path(exists=True, dir_okay=False))
@click.argument("count", type=int)
@click.option("--out", type=click.Path(dir_okay=False), help="Where to write it (default: beside SCENARIO, "
              "named after its run name, e.g. sabatini-1000.toml).")
def scale(scenario: str, count: int, out: str | None) -> None:
    """Write SCENARIO with [dispersion].count = COUNT and the count in its run name: each spacecraft keeps
    its own along-track slot, so the string grows with COUNT and the density is the base's (docs/scaling.md).
    The file is loaded back through the scenario schema; the initial density of both is printed."""
    from swarmhil.deploy.scale import write_scaled  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    try:
        path, base, scaled = write_scaled(scenario, count, out)
    except ValueError as exc:  # a ScenarioError naming the file and the field: one line, exit code 2 (docs/cli.md)
        click.echo(f"error: {' '.join(str(exc).split())}", err=True)
        sys.exit(2)
    click.echo(f"wrote {path}")
    for tag, d in (("base", base), ("scaled", scaled)):
        click.echo(f"  {tag:6s} {d.count:5d} spacecraft, along-track span {d.along_track_span_m / 1000.0:7.1f} km, "
                   f"{d.per_km:.2f} per km, each sees {d.mean_seen:.2f} at t = 0 (mean)")
