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
from swarmhil.dashboards.navreport.analysis import H, RunNav, analyse_run
from swarmhil.dashboards.navreport.diagnosis import (StepSeries, edge_line, splits, splits_summary, step_series,
                                                    step_series_json, step_summary)
from swarmhil.dashboards.navreport.figures import fig_steps, nav_figures
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


def diagnosis_rows(s: dict[str, Any]) -> list[tuple[str, str]]:
    """(quantity, value) rows of the splits and the per-step comparisons (nav_summary.json "splits", "per_step")."""
    sp, st = s.get("splits"), s.get("per_step")
    out = []
    if sp is not None:
        first = (f"; first at step {sp['split_steps'][0]}, edges lost: {', '.join(sp['lost_edges_at_first_split']) or 'none'}"
                 if sp["splits"] else "")
        out.append(("splits of the visibility graph (1 -> more weakly connected components)", f"{sp['splits']}{first}"))
    if st is not None and not st.get("tracks_recorded", True):
        out.append(("visible pairs without a track, false tracks, swaps", "n/a: no tracks in the telemetry"))
    elif st is not None:
        out += [("visible pair-steps: missed (never tracked) / lost tracks (had one the step before) / observer sent no telemetry",
                 f"{st['visible_pair_steps']}: {st['missed_pair_steps']} / {st['lost_tracks']} / "
                 f"{st.get('visible_pair_steps_without_telemetry', 0)}"),
                (f"false tracks (nearest true neighbour > max({_fmt(st['false_gate']['gate_m'])} m, "
                 f"{_fmt(st['false_gate']['gate_fraction_of_estimated_range'])} x range)): tracks / rows",
                 f"{st['false_tracks']} / {st['false_track_rows']}"),
                ("track swaps (matched to another true neighbour than before) / duplicate track rows",
                 f"{st['swaps']} / {st['duplicate_track_rows']}"),
                ("track breaks (a tracked pair's track replaced by a new one from one step to the next)", str(st["breaks"]))]
    return out


def _g(x: Any, d: int = 3) -> str:
    return "-" if x is None else _fmt(float(x), d)


def _side_cells(v: dict[str, Any]) -> list[str]:
    if not v:
        return ["-"] * 8
    if v.get("had_track"):
        track = f"{v['id']}{' (false)' if v.get('false') else ''}"
    else:
        track = "none"
    ctrl = f"acting: {v['behaviour']}" if v.get("controller_acting") else "not acting"
    return [track, ctrl, _g(v.get("true_range_m"), 4), _g(v.get("range_err_m")),
            f"{_g(v.get('true_fov_margin_px'))} / {_g(v.get('fov_margin_px'))}",
            f"{_g(v.get('da_err_m'))} / {_g(v.get('de_err_m'))} / {_g(v.get('di_err_m'))}",
            _g(v.get("max_sigma_gained_roe_m")),
            f"{v['steps_tracked']} / {v['steps_acted_on']} of {v['steps_in_window']}"]


EDGE_HEADER = ["edge", "last seen step", "lost by", "side", "track", "controller", "true range [m]", "range error [m]",
               "FOV margin true / estimated [px]", "error a.da / |a.de| / |a.di| [m]", "max 1-sigma a.da, a.de, a.di [m]",
               "steps tracked / acted on, window"]
BELIEF_HEADER = ["step", "visible", "track", "controller (accel. towards it [mm/s^2])", "true range [m]", "est. range [m]",
                 "range rate true / est. [mm/s]", "FOV margin true / est. [px]",
                 "error a.da / |a.de| / |a.di| [m]", "velocity error [mm/s]", "max 1-sigma [m]", "NEES"]


def _belief_cells(e: dict[str, Any]) -> list[str]:
    tr, dec, tru = e["track"], e["decision"], e["truth"]
    ctrl = "-"
    if dec:
        acc = dec.get("accel_towards_neighbour_mps2")
        ctrl = f"{dec['behaviour']} ({_g(None if acc is None else 1e3 * acc)})"
    rr = lambda x: None if x is None else 1e3 * x  # noqa: E731
    if tr is None:  # with ideal sensing, the error of the ROE the decision used
        roe = "-"
        if dec and None not in dec["roe_jk_err_m"]:
            d = dec["roe_jk_err_m"]
            roe = f"{_g(-d[0])} / {_g(math.hypot(d[2], d[3]))} / {_g(math.hypot(d[4], d[5]))} (decision)"
        return [str(e["step"]), _fmt(e["truly_visible"]), "none", ctrl, _g(tru["range_m"], 4), "-",
                f"{_g(rr(tru['range_rate_mps']))} / -", f"{_g(tru['fov_margin_px'])} / -", roe, "-", "-", "-"]
    sig = max(tr["sigma_roe_m"][i] for i in (0, 2, 3, 4, 5)) if tr["sigma_roe_m"] else None
    vel = None if tr["velocity_err_mps"] is None else 1e3 * tr["velocity_err_mps"]
    return [str(e["step"]), _fmt(e["truly_visible"]), tr["id"] + (" (false)" if tr["false"] else ""), ctrl,
            _g(tru["range_m"], 4), _g(tr["range_m"], 4), f"{_g(rr(tru['range_rate_mps']))} / {_g(rr(tr['range_rate_mps']))}",
            f"{_g(tru['fov_margin_px'])} / {_g(tr['fov_margin_px'])}",
            f"{_g(tr['da_err_m'])} / {_g(tr['de_err_m'])} / {_g(tr['di_err_m'])}", _g(vel), _g(sig), _g(tr["nees"])]


def _edge_rows(e: dict[str, Any]) -> list[list[str]]:
    name = f"{e['observer']} -> {e['neighbour']}"
    last = str(e["last_seen_step"]) + ("" if e["lost_at_split"] else " (before)")
    cause = "+".join(e["cause"]) or "?"
    return [[name, last, cause, f"{e['observer']} about {e['neighbour']}", *_side_cells(e.get("observer_view", {}))],
            ["", "", "", f"{e['neighbour']} about {e['observer']}", *_side_cells(e.get("neighbour_view", {}))]]


def _split_title(sp: dict[str, Any]) -> str:
    comps = " | ".join("{" + ", ".join(c) + "}" for c in sp["components"])
    return (f"Split at step {sp['step']} (t = {_fmt(sp['t_s'], 6)} s, {_fmt(sp['t_s'] / H)} h): 1 -> "
            f"{len(sp['components'])} components {comps}; window from step {sp['window_start_step']}")


def splits_markdown(sps: list[dict[str, Any]], max_detailed: int = 20) -> str:
    """nav_splits.md: each split, its lost edges (both sides at the last step each was seen) and the
    observer's belief step by step."""
    if not sps:
        return "No split: the visibility digraph never went from one weakly connected component to more.\n"
    parts = [f"{len(sps)} split(s) of the visibility digraph (dashboards/navreport/diagnosis.py; all in nav_splits.json).\n"]
    for sp in sps[:max_detailed]:
        parts.append(f"## {_split_title(sp)}\n")
        parts += [f"- {edge_line(sp, e)}" for e in sp["lost_edges"]]
        parts.append("")
        parts.append(_markdown(EDGE_HEADER, [r for e in sp["lost_edges"] for r in _edge_rows(e)]))
        for e in sp["lost_edges"]:
            for side, key in ((f"{e['observer']} about {e['neighbour']}", "belief_observer"),
                              (f"{e['neighbour']} about {e['observer']}", "belief_neighbour")):
                b = e.get(key) or []
                if key == "belief_neighbour" and not any(x["track"] or x["decision"] for x in b):
                    parts.append(f"{side}: no track and no decision over the window.\n")
                    continue
                parts.append(f"{side}, step by step:\n")
                parts.append(_markdown(BELIEF_HEADER, [_belief_cells(x) for x in b]))
    if len(sps) > max_detailed:
        parts.append(f"... and {len(sps) - max_detailed} more at steps {', '.join(str(s['step']) for s in sps[max_detailed:])}\n")
    return "\n".join(parts)


def splits_text(navreport_dir: str | Path, max_splits: int = 3) -> str:
    """A few lines for the terminal: the splits of a run (from its nav_splits.json) and the lost edges of the first."""
    doc = json.loads((Path(navreport_dir) / "nav_splits.json").read_text())
    sps = doc["splits"]
    if not sps:
        return f"{doc['run']}: no split of the visibility graph\n"
    lines = [f"{doc['run']}: {len(sps)} split(s) of the visibility graph at steps "
             f"{', '.join(str(s['step']) for s in sps[:20])}{' ...' if len(sps) > 20 else ''}"]
    for sp in sps[:max_splits]:
        lines.append(f"  {_split_title(sp)}")
        lines += [f"    {edge_line(sp, e)}" for e in sp["lost_edges"]]
    return "\n".join(lines) + "\n"


def _html_table(header: list[str], rows: list[list[str]]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    return "<table><tr>" + th + "</tr>" + "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows) + "</table>"


def splits_html(sps: list[dict[str, Any]], max_detailed: int = 20) -> str:
    """The splits section of the page (same content as nav_splits.md)."""
    if not sps:
        return "<p>No split: the visibility digraph never went from one weakly connected component to more.</p>"
    out = [f"<p>{len(sps)} split(s). Lost edges: the visibility edges j -> k (j sees k) that held the new components "
           "together; each with why it went (truth geometry), and what each side's navigation held at the last step "
           "the edge existed and step by step before (definitions: dashboards/navreport/diagnosis.py; every number in "
           "nav_splits.json, text in nav_splits.md).</p>"]
    for sp in sps[:max_detailed]:
        out.append(f"<h3>{html.escape(_split_title(sp))}</h3>")
        out.append(_html_table(EDGE_HEADER, [r for e in sp["lost_edges"] for r in _edge_rows(e)]))
        for e in sp["lost_edges"]:
            b = e.get("belief_observer") or []
            out.append(f"<details><summary>{html.escape(e['observer'])} about {html.escape(e['neighbour'])}, step by step"
                       f"</summary>{_html_table(BELIEF_HEADER, [_belief_cells(x) for x in b])}</details>")
            b = e.get("belief_neighbour") or []
            if any(x["track"] or x["decision"] for x in b):
                out.append(f"<details><summary>{html.escape(e['neighbour'])} about {html.escape(e['observer'])}, step by "
                           f"step</summary>{_html_table(BELIEF_HEADER, [_belief_cells(x) for x in b])}</details>")
    if len(sps) > max_detailed:
        out.append(f"<p>... and {len(sps) - max_detailed} more at steps "
                   f"{html.escape(', '.join(str(s['step']) for s in sps[max_detailed:]))}.</p>")
    return "".join(out)


def layers_html(st: dict[str, Any]) -> str:
    """Per layer: rows compared, median of the per-step medians, worst value and its step."""
    rows = []
    for layer, qs in st.get("layers", {}).items():
        for name, b in qs.items():
            rows.append([layer, name, str(b["rows"]), _g(b["median_of_step_medians"]), _g(b["max"]),
                         "-" if b["worst_step"] is None else str(b["worst_step"])])
    return ("<p>Each navigation layer against truth, per step (tracks: every matched track; used: those the "
            "controller acted on; decisions: the ROE each behaviour decision used). Series per step: nav_steps.json.</p>"
            + _html_table(["layer", "error", "rows", "median of the per-step medians", "max", "step of the max"], rows))


def nav_diagnosis(nav: RunNav, out: Path, prefix: str = "") -> tuple[list[dict[str, Any]], StepSeries, list[dict[str, Any]]]:
    """The splits and the per-step comparisons of an analysed run (diagnosis.py), their totals put into
    nav.summary ("splits", "per_step"), and the two page sections (the per-step figure written into out)."""
    sps = splits(nav)
    steps = step_series(nav)
    nav.summary["splits"] = splits_summary(sps)
    nav.summary["per_step"] = step_summary(steps)
    steps_fig = figures_of(out, [(fig_steps(steps, [s["t_s"] for s in sps], out / f"{prefix}steps.png"),
                                  "Per step: weakly connected components of the visibility digraph (splits: red lines); "
                                  "visible pairs with no matched track (missed, lost), false tracks, swaps, breaks, "
                                  "duplicates; median (solid) and max (dotted) error of each layer.")])
    sections = [{"anchor": "splits", "title": "Splits of the swarm: the visibility edges lost and what navigation believed",
                 "html": splits_html(sps), "figures": []},
                {"anchor": "per-step", "title": "Each navigation layer against truth, per step",
                 "html": layers_html(nav.summary["per_step"]), "figures": steps_fig}]
    return sps, steps, sections


def write_nav_report(run_dir: str | Path) -> Path:
    """Navigation error of a run against truth: run_dir/navreport/index.html (+ PNGs, nav_summary.json,
    nav_table.md, nav_splits.json / .md, nav_steps.json). Returns the path of index.html."""
    run_dir = Path(run_dir)
    nav = analyse_run(run_dir)
    out = run_dir / "navreport"
    out.mkdir(exist_ok=True)
    sps, steps, sections = nav_diagnosis(nav, out)
    (out / "nav_summary.json").write_text(json.dumps(nav.summary, indent=1))
    (out / "nav_splits.json").write_text(json.dumps({"definitions": "dashboards/navreport/diagnosis.py", "run": nav.truth.run,
                                                     "splits": sps}, indent=1))
    (out / "nav_splits.md").write_text(splits_markdown(sps))
    (out / "nav_steps.json").write_text(json.dumps(step_series_json(steps)))
    table = nav_table_rows(nav.summary) + diagnosis_rows(nav.summary)
    (out / "nav_table.md").write_text(_markdown(["quantity", "value"], [list(r) for r in table]))
    figs = nav_figures(nav, out)
    render("page.html", out / "index.html", title=f"Navigation error: {nav.truth.run}",
           head=[(k, html.escape(v)) for k, v in table], sections=sections,
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
    # connectivity and separations: paper 002's metrics hook (missions/p002_sabatini/report/metrics.py), where it ran
    c, cv, ca = met.get("connectivity", {}), met.get("closest_visible_steady", {}), met["closest_approach"]
    cw = met.get("closest_visible_whole_run", {})
    used = nav.get("tracks_used_by_controller", {})
    dec = nav.get("decision_roe_error", {})
    return {
        "label": label or summary.get("scenario") or run_dir.name, "run": summary.get("run"), "dir": str(run_dir),
        "duration_h": met["t_end_s"] / H,
        "delta_v_total_mps": met["control"]["delta_v_total_mps"],
        "delta_v_last_hour_mps": met["control"]["delta_v_last_hour_mps"],
        "delta_v_steady_mps": met["control"]["delta_v_in_steady_window_mps"],
        "weakly_connected_fraction": c.get("weakly_connected_fraction"),
        "orbit_union_weakly_connected_fraction": c.get("orbit_union_weakly_connected_fraction"),
        "max_components": c.get("max_components"),
        "along_track_min_m": cw.get("along_track_m", {}).get("min"),
        "along_track_p05_steady_m": cv.get("along_track_m", {}).get("p05"),
        "radial_p05_steady_m": cv.get("radial_m", {}).get("p05"),
        "cross_p05_steady_m": cv.get("cross_track_m", {}).get("p05"),
        "closest_approach_m": ca["all_pairs"]["distance_m"],
        "closest_approach_visible_m": ca.get("visible_pairs", {}).get("distance_m"),
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

