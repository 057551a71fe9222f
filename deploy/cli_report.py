"""`swarmhil report RUN_DIR` and `swarmhil sweep SCENARIO --param P --values ...` (issue 3).

The sweep runs one in-process run per value, `--jobs` at a time on the executor of `swarmhil
campaign` (a process pool, or Dask: deploy/campaign.py `execute`), writes
each case's report, and one sweep report (dV and connectivity against the parameter, paper 002
Figs. 30-31). `--param` is a dotted path into the scenario TOML (`sensing.roe_noise_fraction`,
`controller.params.k_ecc`, `dispersion.along_track_spacing_m`, `run.seed`, ...); values are
comma-separated numbers, strings or JSON lists (`[20,40,30,30,30,30],[10,40,15,15,15,15]`).
`--seeds` repeats every value with each [run].seed (for a generated dispersion the seed also
changes the initial conditions; with explicit [[spacecraft]] it changes only the noise).
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import click


def parse_values(text: str) -> list[Any]:
    """Split on commas outside brackets; each item as JSON (number, list, bool) or else a string."""
    items, depth, cur = [], 0, ""
    for ch in text:
        if ch == "," and depth == 0:
            items.append(cur)
            cur = ""
            continue
        depth += ch == "["
        depth -= ch == "]"
        cur += ch
    items.append(cur)
    out = []
    for it in (s.strip() for s in items):
        if not it:
            raise click.BadParameter(f"empty value in {text!r}")
        try:
            out.append(json.loads(it))
        except ValueError:
            out.append(it)
    return out


def set_param(doc: dict[str, Any], param: str, value: Any) -> dict[str, Any]:
    """A copy of the scenario document with doc[a][b]... = value for param 'a.b...' (the path rules
    of `--set`, deploy/overrides.py)."""
    from swarmhil.deploy.overrides import OverrideError, set_path  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    try:
        return set_path(doc, param, value)
    except OverrideError as exc:
        raise click.BadParameter(str(exc)) from None


def _label(param: str, value: Any, seed: int | None) -> str:
    v = json.dumps(value, separators=(",", ":")) if not isinstance(value, str) else value
    safe = "".join(c if c.isalnum() or c in "._-" else "_" for c in v)[:40]
    return f"{param.split('.')[-1]}={safe}" + ("" if seed is None else f"_seed{seed}")


def run_case(scenario_path: str, param: str, value: Any, seed: int | None, duration_s: float | None,
             out_dir: str, run_id: str, figures: bool = True, sets: tuple[str, ...] = (),
             record: str = "all") -> dict[str, Any]:
    """One sweep case (on a worker): in-process run, then its report. Errors are returned."""
    from swarmhil.dashboards.report import write_report  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.launcher import run_in_process  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.scenario import parse_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.sensors import CameraGeometry  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    case: dict[str, Any] = {"value": value, "seed": seed, "dir": out_dir, "run": run_id}
    t0 = time.monotonic()
    try:
        from swarmhil.deploy.overrides import apply_sets  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
        from swarmhil.deploy.scenario import read_document  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        doc = set_param(apply_sets(read_document(scenario_path)[0], list(sets)), param, value)
        sc = parse_scenario(doc, Path(scenario_path).name).with_overrides(duration_s=duration_s, seed=seed)
        sc.sets = tuple(sets) + (f"{param}={json.dumps(value)}",)
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "scenario_doc.json").write_text(json.dumps(doc, indent=1, default=str))
        res = run_in_process(sc, out, run_id, progress=False, record=record)
        cam = CameraGeometry(sc.camera["detection_range_m"], sc.camera["image_px"], sc.camera["focal_px"])
        write_report(out, cam=cam, figures=figures)
        case["delta_v_total_mps"] = res.summary["delta_v_total_mps"]
    except Exception as exc:  # noqa: BLE001 - reported in the sweep table, the other cases go on
        case["error"] = f"{type(exc).__name__}: {exc}"
    case["wall_s"] = time.monotonic() - t0
    return case


@click.command("report")
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False))
@click.option("--steady-from-h", type=float, help="Start of the steady-state window [h] (default: last sixth of the run).")
@click.option("--scenario", "scenario", type=click.Path(exists=True, dir_okay=False),
              help="Scenario file to take the camera from (default: the run's, else the paper's camera).")
@click.option("--vector/--no-vector", default=True, show_default=True,
              help="Also save every figure as SVG and PDF (for papers) beside its PNG.")
def report(run_dir: str, steady_from_h: float | None, scenario: str | None, vector: bool) -> None:
    """Metrics (into RUN_DIR/summary.json) and the report site RUN_DIR/report/index.html from RUN_DIR/run.mcap:
    mission metrics and sections, navigation, bandwidth, events and the data tables (docs/analysis.md).

    For a sweep directory (with sweep.json), every case is reported again and the sweep report rewritten.
    """
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.dashboards.report import sections_for, write_report, write_sweep_report  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.cli_inputs import check_run_dir  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    for mod in ("matplotlib", "jinja2", "plotly", "pandas", "pyarrow"):
        require(mod, "swarmhil report (its site, figures and tables)")
    from swarmhil.plant.sensors import CameraGeometry  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if not (Path(run_dir) / "sweep.json").is_file():
        check_run_dir(run_dir)
    cam = None
    if scenario:
        from swarmhil.deploy.scenario import load_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        c = load_scenario(scenario).camera
        cam = CameraGeometry(c["detection_range_m"], c["image_px"], c["focal_px"])
    steady_s = None if steady_from_h is None else steady_from_h * 3600.0
    sweep_file = Path(run_dir) / "sweep.json"
    try:
        if sweep_file.is_file():
            sw = json.loads(sweep_file.read_text())
            for case in sw["cases"]:
                if not case.get("error"):
                    d = Path(case["dir"])
                    write_report(d, cam=cam, steady_from_s=steady_s, figures=(d / "report" / "index.html").is_file())
            click.echo(f"wrote {write_sweep_report(run_dir, sw['param'], sw['cases'])}")
            return
        page = write_report(run_dir, cam=cam, steady_from_s=steady_s, export=("svg", "pdf") if vector else ())
    except (OSError, ValueError) as exc:
        raise click.ClickException(str(exc)) from None
    summary = json.loads((Path(run_dir) / "summary.json").read_text())
    met = summary["metrics"]
    # what every run has (issue 25: a mission's own numbers are in its section of the page)
    sections = [name for name, _fn in sections_for(summary.get("config") or {})]
    click.echo(f"total dV {met['control']['delta_v_total_mps']:.4f} m/s; closest approach "
               f"{met['closest_approach']['all_pairs']['distance_m']:.2f} m; sections: {', '.join(sections) or 'none'}")
    click.echo(f"wrote {page}")


@click.command("sweep")
@click.argument("scenario", type=click.Path(exists=True, dir_okay=False))
@click.option("--param", required=True, help="Dotted scenario path, e.g. sensing.roe_noise_fraction.")
@click.option("--values", "values_text", required=True, help="Comma-separated values, e.g. 0,0.1,0.2,0.3,0.35.")
@click.option("--seeds", help="Comma-separated [run].seed values; every value is run with each.")
@click.option("--out", "out", type=click.Path(file_okay=False), help="Output directory (default runs/sweep-<scenario>-<time>).")
@click.option("--jobs", type=int, default=2, show_default=True, help="Cases run at once on this machine.")
@click.option("--executor", type=click.Choice(["local", "dask"]), default="local", show_default=True,
              help="As `swarmhil campaign`: local: a process pool; dask: Dask distributed (a LocalCluster on 127.0.0.1, or --scheduler).")
@click.option("--scheduler", metavar="ADDRESS", help="Dask scheduler of a running cluster (tcp://host:8786); implies dask.")
@click.option("--record", type=click.Choice(["all", "truth"]), default="all", show_default=True,
              help="all: every message; truth: the truth and events only, flight software run as one batch where "
                   "the scenario allows (same truth; the case reports of paper 002 need only the truth).")
@click.option("--duration", type=float, help="Simulated seconds (overrides [run].duration_s).")
@click.option("--case-reports/--no-case-reports", default=True, show_default=True,
              help="Write each case's own report (figures); the metrics are always computed.")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Override a scenario field for every case (repeatable; value parsed as TOML).")
def sweep(scenario: str, param: str, values_text: str, seeds: str | None, out: str | None, jobs: int,
          executor: str, scheduler: str | None, record: str, duration: float | None, case_reports: bool,
          sets: tuple[str, ...]) -> None:
    """Run SCENARIO once per value of --param (in-process runs in parallel) and write one report."""
    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.dashboards.report import write_sweep_report  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.campaign import execute  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.launcher import new_run_id  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    require("matplotlib", "swarmhil sweep (its report's figures)")  # before any case runs
    from swarmhil.deploy.scenario import ScenarioError, parse_scenario, read_document  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    values = parse_values(values_text)
    try:
        seed_list: list[int | None] = [None] if not seeds else [int(s) for s in seeds.split(",")]
    except ValueError:
        raise click.BadParameter(f"{seeds!r}: comma-separated integers, e.g. 1,2,3", param_hint="--seeds") from None
    from swarmhil.deploy.overrides import OverrideError, apply_sets  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    try:  # fail fast on a bad parameter or value, before starting anything
        doc = apply_sets(read_document(scenario)[0], list(sets))
        for v in values:
            parse_scenario(set_param(doc, param, v), Path(scenario).name)
    except (ScenarioError, OverrideError, click.BadParameter) as exc:
        msg = exc.format_message() if isinstance(exc, click.BadParameter) else str(exc)
        click.echo(f"error: {msg}", err=True)
        sys.exit(2)
    name = doc.get("run", {}).get("name", Path(scenario).stem)
    out_dir = Path(out) if out else Path("runs") / f"sweep-{new_run_id(name)}"
    out_dir.mkdir(parents=True, exist_ok=True)
    cases = [(v, s) for v in values for s in seed_list]
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    results: list[dict[str, Any]] = [{} for _ in cases]
    t0 = time.monotonic()
    calls = {}
    for i, (v, s) in enumerate(cases):
        calls[i] = (str(Path(scenario).resolve()), param, v, s, duration, str(out_dir / _label(param, v, s)),
                    f"{new_run_id(name)}-c{i:02d}", case_reports, tuple(sets), record)

    def show(i: int, r: dict[str, Any]) -> None:
        results[i] = r
        status = r.get("error") or f"total dV {r['delta_v_total_mps']:.4f} m/s"
        click.echo(f"[{time.monotonic() - t0:7.0f} s] {param}={r['value']} seed={r['seed']}: {status}")

    def lost(i: int, err: str) -> dict[str, Any]:  # the worker died: the case is a failed one
        return {"value": cases[i][0], "seed": cases[i][1], "dir": calls[i][5], "run": calls[i][6], "error": err}

    execute(run_case, calls, executor="dask" if scheduler else executor, jobs=jobs, scheduler=scheduler,
            on_row=show, lost=lost)
    page = write_sweep_report(out_dir, param, results)
    click.echo(f"wrote {page}")
    if any(r.get("error") for r in results):
        sys.exit(1)
