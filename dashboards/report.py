"""Reports of a run and of a sweep, in the spirit of paper 002's Figs. 7-22 and 30-31.

`write_report(run_dir)` reads run_dir/run.mcap (truth only, dashboards/truth_io.py), computes the
metrics (dashboards/metrics.py), adds them to run_dir/summary.json under "metrics" and writes the
report site run_dir/report/ (dashboards/site.py): index.html with the overview every run has (dV,
closest approach, link traffic, events), then the section of each mission the run flew
(dashboards/sections/; paper 002's metrics and Figs. 7-22 are its room's, missions/p002_sabatini/report.py), and
the pages and tables the site links. `write_sweep_report(sweep_dir, cases)` does the same for a
parameter sweep (dV and connectivity against the parameter, Figs. 30-31).
"""
from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from swarmhil.dashboards.figstyle import exporting, integer_axis, legend, span_text, time_unit, window_text
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.frames import metrics_series_frame
from swarmhil.dashboards.kit import approach, figures_of, fmt, render
from swarmhil.dashboards.metrics import SwarmMetrics
from swarmhil.dashboards.run_config import run_camera, run_config
from swarmhil.dashboards.run_metrics import SERIES, read_summary, store_metrics
from swarmhil.dashboards.sections import SectionContext, sections_for
from swarmhil.dashboards.sections.contact import overview_rows
from swarmhil.dashboards.site import write_site
from swarmhil.dashboards.truth_io import TruthArrays, read_truth
from swarmhil.plant.sensors import CameraGeometry

H = 3600.0


# --- the overview ----------------------------------------------------------------------------------------
def _headline(summary: dict[str, Any], met: dict[str, Any]) -> list[tuple[str, str]]:
    """What every run has, whatever its mission: run, scenario, spacecraft and duration, dV (total and
    per spacecraft), acceleration, closest approach. The link traffic and the events follow
    (dashboards/site.py), then each mission's own section (dashboards/sections/)."""
    ctl, ca = met["control"], met["closest_approach"]
    run_s = met["t_end_s"] - met.get("t_start_s", 0.0)
    _hour_s, hour = window_text(run_s, H)
    per_sc = ctl.get("delta_v_per_spacecraft_mps") or {}
    return [
        ("run", fmt(summary.get("run"))),
        ("scenario / controller", f"{fmt(summary.get('scenario'))} / {fmt(summary.get('controller'))}"),
        ("spacecraft, duration", f"{summary.get('agents', '?')} spacecraft, {span_text(run_s)} ({met['steps']} steps)"),
        ("total dV [m/s]", f"{fmt(ctl['delta_v_total_mps'], 4)} (max per spacecraft {fmt(ctl['delta_v_max_spacecraft_mps'])}; "
                           f"{fmt(ctl['delta_v_last_hour_mps'])} over the {hour}; 95 % spent by "
                           f"t = {span_text(ctl['t_95pct_delta_v_s'])})"),
        ("dV per spacecraft [m/s]", ", ".join(f"{html.escape(str(k))} {fmt(v)}" for k, v in per_sc.items()) or "n/a"),
        ("max |a| [m/s^2]", fmt(ctl["accel_max_mps2"])),
        ("closest approach, all pairs", approach(ca["all_pairs"])),
    ]


def write_report(run_dir: str | Path, *, cam: CameraGeometry | None = None, steady_from_s: float | None = None,
                 projection_orbits: float = 3.0, figures: bool = True, interactive: bool = True,
                 export: tuple[str, ...] = ("svg", "pdf")) -> Path:
    """Metrics into run_dir/summary.json["metrics"] and their time series into
    run_dir/metrics_series.npz; with `figures`, the report site run_dir/report/ (dashboards/site.py):
    index.html and its pages, the figures (PNG, SVG, PDF; Plotly where there are many lines when
    `interactive`; the vector copies of `export`) and the tables of report/data/."""
    with exporting(export):
        return _write_report(Path(run_dir), cam, steady_from_s, projection_orbits, figures, interactive)


def _write_report(run_dir: Path, cam: CameraGeometry | None, steady_from_s: float | None, projection_orbits: float,
                  figures: bool, interactive: bool) -> Path:
    spath = run_dir / "summary.json"
    summary = read_summary(run_dir)
    cam = cam or run_camera(run_dir, summary)
    truth = read_truth(run_dir / "run.mcap", summary.get("run"))
    m, met = store_metrics(run_dir, summary, truth, cam, steady_from_s)
    if not figures:
        return spath
    out = run_dir / "report"
    out.mkdir(exist_ok=True)
    summary.setdefault("config", run_config(run_dir) or {})
    sections = _mission_sections(run_dir, out, summary, truth, m, interactive, projection_orbits)
    for s in sections:
        s["figures"] = figures_of(out, s["figures"])
    spath.write_text(json.dumps(summary, indent=1))
    title = f"swarmhil report: {summary.get('scenario', truth.run)}"
    return write_site(run_dir, out, title, overview_rows(summary) + _headline(summary, met), [], sections,
                      metrics_series_frame(m),
                      summary["metrics"],
                      intro="<p>Metrics computed from the recorded truth (dashboards/metrics.py); the full numbers are in "
                            "<code>summary.json</code> under <code>metrics</code> and in <a href=\"data.html\">the data "
                            "tables</a>.</p>")


def _mission_sections(run_dir: Path, out: Path, summary: dict[str, Any], truth: TruthArrays, m: SwarmMetrics,
                      interactive: bool, projection_orbits: float | None) -> list[dict[str, Any]]:
    """Run every registered report section that applies to this run (dashboards/sections/): its
    metrics, when it has any, into summary["metrics"][name]; returns {anchor, title, html, figures}
    per section (figures: (PNG, caption) pairs or site figures)."""
    cfg = summary["config"]  # write_report filled it from the recording
    blocks = []
    for name, fn in sections_for(cfg):
        res = fn(SectionContext(run_dir, run_dir / "run.mcap", out, summary, cfg, truth, m, interactive,
                                projection_orbits))
        if res.metrics:
            summary["metrics"][name] = res.metrics
        blocks.append({"anchor": name, "title": res.title, "html": res.html, "figures": list(res.figures)})
    return blocks


# --- sweep -------------------------------------------------------------------------------------------------
def write_sweep_report(sweep_dir: str | Path, param: str, cases: Sequence[dict[str, Any]]) -> Path:
    """Figs. 30-31 for a sweep. `cases`: dicts with value, seed, dir (a run dir whose summary.json
    already holds "metrics"), and optionally error. Writes sweep_dir/report/index.html and sweep.json."""
    plt = _plt()
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for c in cases:
        row = {"value": c["value"], "seed": c.get("seed"), "dir": str(c["dir"]), "error": c.get("error")}
        s = Path(c["dir"]) / "summary.json"
        if not c.get("error") and s.is_file():
            met = json.loads(s.read_text()).get("metrics", {})
            if met:
                row.update({
                    "delta_v_total_mps": met["control"]["delta_v_total_mps"],
                    "delta_v_last_hour_mps": met["control"]["delta_v_last_hour_mps"],
                    "weakly_connected_fraction": met["connectivity"]["weakly_connected_fraction"],
                    "orbit_union_weakly_connected_fraction":
                        met["connectivity"].get("orbit_union_weakly_connected_fraction"),
                    "always_weakly_connected": met["connectivity"]["always_weakly_connected"],
                    "max_components": met["connectivity"]["max_components"],
                    "components_end": met["connectivity"]["components_end"],
                    "first_split_t_s": met["connectivity"]["first_split_t_s"],
                    "closest_visible_pairs_m": met["closest_approach"]["visible_pairs"]["distance_m"],
                    "closest_non_visible_pairs_m": met["closest_approach"]["non_visible_pairs"]["distance_m"],
                    "along_track_min_steady_m": met["closest_visible_steady"]["along_track_m"].get("min"),
                })
        rows.append(row)
    (sweep_dir / "sweep.json").write_text(json.dumps({"param": param, "cases": rows}, indent=1))
    good = [r for r in rows if "delta_v_total_mps" in r]
    figs = []
    if good:
        xs = np.array([float(r["value"]) if _is_number(r["value"]) else i for i, r in enumerate(good)])
        fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        ax[0].plot(xs, [r["delta_v_total_mps"] for r in good], "o", color="C0")
        for x in np.unique(xs):
            v = [r["delta_v_total_mps"] for r, xx in zip(good, xs) if xx == x]
            ax[0].plot([x], [np.mean(v)], "_", ms=20, color="k")
        ax[0].set_ylabel("total dV [m/s]")
        ax[0].set_ylim(bottom=0.0)
        ax[0].set_title(f"Total dV against {param} (paper 002 Fig. 30)")
        ax[1].plot(xs, [r["weakly_connected_fraction"] for r in good], "o", color="C1", label="fraction of steps weakly connected")
        ax[1].plot(xs, [r.get("orbit_union_weakly_connected_fraction") or np.nan for r in good], "s", mfc="none",
                   color="C2", label="fraction weakly connected over the last orbit (union)")
        ax[1].plot(xs, [1.0 / r["max_components"] for r in good], "x", color="C3", label="1 / max components")
        ax[1].set_ylim(-0.05, 1.05)
        ax[1].set_xlabel(param)
        ax[1].legend(loc="lower left")
        ax[1].set_title("Swarm integrity")
        figs.append((_save(fig, out / "sweep_dv_connectivity.png"), "Total dV and connectivity per case (paper Fig. 30)."))
        fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        for i, r in enumerate(good):
            ser = np.load(Path(r["dir"]) / SERIES)
            lab = f"{param}={r['value']}" + (f" seed {r['seed']}" if r.get("seed") is not None else "")
            tu, xl = time_unit(ser["t_s"])
            ax[0].step(ser["t_s"] / tu, ser["n_components"], where="post", lw=0.9, label=lab, color=f"C{i % 10}")
            if "n_components_orbit" in ser:
                ax[1].step(ser["t_s"] / tu, ser["n_components_orbit"], where="post", lw=0.9, color=f"C{i % 10}")
            ax[2].plot(ser["t_s"] / tu, ser["delta_v_total_mps"], lw=0.9, label=lab, color=f"C{i % 10}")
        ax[0].set_ylabel("weakly connected\ncomponents")
        ax[0].set_title("Connectedness per case (paper Fig. 31)")
        legend(ax[0], len(good))
        ax[1].set_ylabel("components of the\nunion over the last orbit")
        ax[2].set_ylabel("total dV [m/s]")
        ax[2].set_xlabel(xl)
        integer_axis(ax[0].yaxis)
        integer_axis(ax[1].yaxis)
        figs.append((_save(fig, out / "sweep_components_dv_time.png"), "Components and total dV over time, per case."))
    head = [("parameter", html.escape(param)), ("cases", str(len(rows)))]
    cols = ["value", "seed", "delta_v_total_mps", "delta_v_last_hour_mps", "weakly_connected_fraction",
            "orbit_union_weakly_connected_fraction", "max_components",
            "components_end", "first_split_t_s", "along_track_min_steady_m", "closest_visible_pairs_m",
            "closest_non_visible_pairs_m", "error"]
    table = "<table><tr>" + "".join(f"<th>{c}</th>" for c in cols + ["report"]) + "</tr>"
    for r in rows:
        case_page = Path(r["dir"]) / "report" / "index.html"
        try:
            href = "../" + case_page.resolve().relative_to(sweep_dir.resolve()).as_posix()
            link = f'<a href="{html.escape(href)}">report</a>' if case_page.is_file() else "metrics only"
        except ValueError:
            link = html.escape(str(case_page))
        table += "<tr>" + "".join(f"<td>{fmt(r.get(c))}</td>" for c in cols) + f"<td>{link}</td></tr>"
    table += "</table>"
    render("page.html", out / "index.html", title=f"swarmhil sweep: {param}", head=head,
           figures=figures_of(out, figs), intro=table)
    return out / "index.html"


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)
