"""The navigation pages: a run's navreport/ (index.html, nav_summary.json, nav_table.md, figures) and the
comparison of runs (comparison.md / .json / .html)."""
from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from swarmhil.dashboards.kit import figures_of, render
from swarmhil.dashboards.navreport.analysis import H, analyse_run
from swarmhil.dashboards.navreport.figures import nav_figures
from swarmhil.dashboards.run_metrics import summary_with_metrics


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, float):
        if not math.isfinite(v):
            return "n/a" if math.isnan(v) else str(v)
        return f"{v:.{digits}g}" if abs(v) < 1e5 else f"{v:.0f}"
    return str(v)


def _mp(block: dict[str, Any], key: str, scale: float = 1.0) -> str:
    b = block.get(key, {})
    if not b.get("count"):
        return "n/a"
    return f"{_fmt(b['median'] * scale)} / {_fmt(b['p95'] * scale)}"


def nav_table_rows(s: dict[str, Any]) -> list[tuple[str, str]]:
    """(quantity, value) rows of a run's navigation summary (median / 95 %)."""
    if not s.get("track_rows"):
        d = s.get("decision_roe_error", {})
        return [("tracks", "none (sensing without a camera pipeline)"),
                ("decision ROE error a.da / a.de / a.di [m] (median / 95 %)",
                 " ; ".join(_mp(d, k) for k in ("da_m", "de_m", "di_m")))]
    out = [("track rows / tracks / median life [steps]",
            f"{s['track_rows']} / {s['tracks']} / {_fmt(s['track_life_steps']['median'])}"),
           ("identity switches (tracks with one)", f"{s['identity_switches']} ({_fmt(100 * s['tracks_with_switch_fraction'])} %)"),
           ("ambiguous association (second candidate < 2x nearest)", f"{_fmt(100 * (s['ambiguous_association_fraction'] or 0))} %"),
           ("coverage of truly visible pairs", f"{_fmt(100 * s.get('coverage_of_visible_pairs', float('nan')))} %"),
           ("rows used by the controller", f"{_fmt(100 * s['used_fraction'])} %")]
    if "coverage_of_visible_pairs_used" in s:
        out += [("visible pairs with a track the controller used", f"{_fmt(100 * s['coverage_of_visible_pairs_used'])} %"),
                ("used rows whose neighbour was not visible", f"{_fmt(100 * (s['used_rows_not_visible_fraction'] or 0))} %"),
                ("weakly connected per step: graph of used tracks / visibility graph",
                 f"{_fmt(100 * s['used_graph_weakly_connected_fraction'])} % / "
                 f"{_fmt(100 * s['visibility_weakly_connected_fraction'])} %")]
    if "held_back_fraction" in s:
        p = lambda v: "-" if v is None else f"{_fmt(100 * v)} %"  # noqa: E731
        b = s["held_back_fraction_by_range"]
        out += [("visible pairs with a track the controller did not use: run / first "
                 f"{_fmt(s['held_back_start_s'] / H)} h / after",
                 f"{p(s['held_back_fraction'])} / {p(s['held_back_fraction_start'])} / {p(s['held_back_fraction_after_start'])}"),
                ("... by true range / detection range 0-0.6 / 0.6-0.9 / 0.9-1",
                 f"{p(b['0-0.6'])} / {p(b['0.6-0.9'])} / {p(b['0.9-1'])}")]
    for label, key in (("all tracks", "all_tracks"), ("used by the controller", "tracks_used_by_controller")):
        b = s[key]
        out += [(f"{label}: position error [m] (median / 95 %)", _mp(b, "position_m")),
                (f"{label}: velocity error [mm/s]", _mp(b, "velocity_mps", 1e3)),
                (f"{label}: a.da / a.dl error [m]", f"{_mp(b, 'roe_da_m')} ; {_mp(b, 'roe_dl_m')}"),
                (f"{label}: a.de / a.di error (norms) [m]", f"{_mp(b, 'roe_de_m')} ; {_mp(b, 'roe_di_m')}"),
                (f"{label}: NEES mean / median / fraction <= chi2(95 %)",
                 "n/a" if not b["nees"].get("count") else
                 f"{_fmt(b['nees']['mean'])} / {_fmt(b['nees']['median'])} / {_fmt(b['nees']['fraction_below_chi2_95'])}")]
    return out


def write_nav_report(run_dir: str | Path) -> Path:
    """Navigation error of a run against truth: run_dir/navreport/index.html (+ PNGs, nav_summary.json,
    nav_table.md). Returns the path of index.html."""
    run_dir = Path(run_dir)
    nav = analyse_run(run_dir)
    out = run_dir / "navreport"
    out.mkdir(exist_ok=True)
    (out / "nav_summary.json").write_text(json.dumps(nav.summary, indent=1))
    table = nav_table_rows(nav.summary)
    (out / "nav_table.md").write_text(_markdown(["quantity", "value"], [list(r) for r in table]))
    figs = nav_figures(nav, out)
    render("page.html", out / "index.html", title=f"Navigation error: {nav.truth.run}",
           head=[(k, html.escape(v)) for k, v in table],
           figures=figures_of(out, figs), intro="<p>Definitions: dashboards/navreport/ (package docstring). Numbers: nav_summary.json.</p>")
    return out / "index.html"


def comparison_row(run_dir: str | Path, label: str | None = None) -> dict[str, Any]:
    """One run's line of the comparison: swarm metrics from truth and its navigation error."""
    run_dir = Path(run_dir)
    nav_path = run_dir / "navreport" / "nav_summary.json"
    if not nav_path.is_file():
        write_nav_report(run_dir)
    nav = json.loads(nav_path.read_text())
    summary = summary_with_metrics(run_dir)
    met = summary["metrics"]
    c, cv, ca = met["connectivity"], met["closest_visible_steady"], met["closest_approach"]
    cw = met.get("closest_visible_whole_run", {})
    used = nav.get("tracks_used_by_controller", {})
    dec = nav.get("decision_roe_error", {})
    return {
        "label": label or summary.get("scenario") or run_dir.name, "run": summary.get("run"), "dir": str(run_dir),
        "duration_h": met["t_end_s"] / H,
        "delta_v_total_mps": met["control"]["delta_v_total_mps"],
        "delta_v_last_hour_mps": met["control"]["delta_v_last_hour_mps"],
        "delta_v_steady_mps": met["control"]["delta_v_in_steady_window_mps"],
        "weakly_connected_fraction": c["weakly_connected_fraction"],
        "orbit_union_weakly_connected_fraction": c.get("orbit_union_weakly_connected_fraction"),
        "max_components": c["max_components"],
        "along_track_min_m": cw.get("along_track_m", {}).get("min"),
        "along_track_p05_steady_m": cv["along_track_m"].get("p05"),
        "radial_p05_steady_m": cv["radial_m"].get("p05"),
        "cross_p05_steady_m": cv["cross_track_m"].get("p05"),
        "closest_approach_m": ca["all_pairs"]["distance_m"],
        "closest_approach_visible_m": ca["visible_pairs"]["distance_m"],
        "nav_position_median_m": used.get("position_m", {}).get("median"),
        "nav_position_p95_m": used.get("position_m", {}).get("p95"),
        "nav_da_median_m": dec.get("da_m", {}).get("median"),
        "nav_da_p95_m": dec.get("da_m", {}).get("p95"),
        "nav_de_median_m": dec.get("de_m", {}).get("median"),
        "nav_di_median_m": dec.get("di_m", {}).get("median"),
        "nees_mean": used.get("nees", {}).get("mean"),
        "coverage": nav.get("coverage_of_visible_pairs"),
    }


COLUMNS = [
    ("label", "run", None),
    ("delta_v_total_mps", "total dV [m/s]", 4),
    ("dv_ratio", "dV / first", 3),
    ("delta_v_steady_mps", "dV in the steady window (last sixth) [m/s]", 3),
    ("weakly_connected_fraction", "weakly connected (fraction of steps)", 4),
    ("orbit_union_weakly_connected_fraction", "weakly connected, union over an orbit", 4),
    ("along_track_min_m", "min along-track to closest visible [m]", 3),
    ("along_track_p05_steady_m", "along-track p05, steady [m]", 3),
    ("radial_p05_steady_m", "radial a.de p05, steady [m]", 3),
    ("cross_p05_steady_m", "cross-track a.di p05, steady [m]", 3),
    ("closest_approach_m", "closest approach [m]", 3),
    ("nav_position_median_m", "position error used, median / 95 % [m]", 3),
    ("nav_da_median_m", "a.da error used, median / 95 % [m]", 3),
    ("nav_de_median_m", "a.de / a.di error used, median [m]", 3),
    ("nees_mean", "NEES mean (6 = consistent)", 3),
    ("coverage", "visible pairs tracked", 3),
]


def _cell(row: dict[str, Any], key: str, digits: int | None) -> str:
    if key == "nav_position_median_m":
        return "-" if row[key] is None else f"{_num(row[key])} / {_num(row['nav_position_p95_m'])}"
    if key == "nav_da_median_m":
        return "-" if row[key] is None else f"{_num(row[key])} / {_num(row['nav_da_p95_m'])}"
    if key == "nav_de_median_m":
        return "-" if row[key] is None else f"{_num(row[key])} / {_num(row['nav_di_median_m'])}"
    v = row.get(key)
    if v is None:
        return "-"
    return _fmt(v, digits) if digits else str(v)


def _num(v: Any) -> str:
    """A number for the table; errors below a nanometre (ideal sensing, rounding only) print as 0."""
    return "-" if v is None else ("0" if abs(v) < 1e-9 else _fmt(v, 3))


def _markdown(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def write_comparison(run_dirs: Sequence[str | Path], out_dir: str | Path, labels: Sequence[str] | None = None) -> Path:
    """comparison.md / .json / .html in out_dir over the runs (the first is the dV reference)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [comparison_row(d, None if labels is None else labels[i]) for i, d in enumerate(run_dirs)]
    ref = rows[0]["delta_v_total_mps"] if rows else 0.0
    for r in rows:
        r["dv_ratio"] = r["delta_v_total_mps"] / ref if ref else None
    header = [h for _, h, _ in COLUMNS]
    cells = [[_cell(r, k, d) for k, _, d in COLUMNS] for r in rows]
    md = _markdown(header, cells)
    (out / "comparison.md").write_text(md)
    (out / "comparison.json").write_text(json.dumps(rows, indent=1))
    th = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    tb = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in cells)
    render("page.html", out / "comparison.html", title="Runs compared",
           intro=f"<table><tr>{th}</tr>{tb}</table><p>Swarm metrics from truth (dashboards/metrics.py), navigation "
                 "error from telemetry against truth (dashboards/navreport/). Separations: closest visible "
                 "neighbour; p05 over the steady window (last sixth of the run).</p>")
    return out / "comparison.md"

