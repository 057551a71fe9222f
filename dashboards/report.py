"""Reports of a run and of a sweep, in the spirit of paper 002's Figs. 7-22 and 30-31.

`write_report(run_dir)` reads run_dir/run.mcap (truth only, dashboards/truth_io.py), computes the
metrics (dashboards/metrics.py), adds them to run_dir/summary.json under "metrics" and writes the
report site run_dir/report/ (dashboards/site.py): index.html with the headline metrics, paper 002's
figures (many-line ones as LineFigure specs, drawn static by dashboards/figstyle.py and
interactive by dashboards/interactive.py) and the mission sections, and the pages and tables the
site links. `write_sweep_report(sweep_dir, cases)` does the same for a parameter sweep (dV and
connectivity against the parameter, Figs. 30-31).
"""
from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from dashboards.figstyle import Line, LineFigure, Panel, integer_axis, legend, span_text, time_axis, time_unit, window_text
from dashboards.figstyle import colors as _colors  # the names the mission sections import
from dashboards.figstyle import pyplot as _plt
from dashboards.figstyle import save as _save
from dashboards.metrics import D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN, SwarmMetrics, compute_metrics, relative_to_com
from dashboards.run_config import camera_from_config, run_config
from dashboards.truth_io import TruthArrays, read_truth
from plant.sensors import CameraGeometry

H = 3600.0
SERIES = "metrics_series.npz"  # per-step series a sweep report overlays


# --- run figures --------------------------------------------------------------------------------------
# Figures with one line per spacecraft are LineFigure specs (dashboards/figstyle.py): drawn static
# (PNG, SVG, PDF) and interactive (Plotly, dashboards/interactive.py) from the same data.
def _steady_span(m: SwarmMetrics, x: np.ndarray) -> tuple[float, float] | None:
    return (float(x[np.argmax(m.steady)]), float(x[-1])) if m.steady.any() else None


def _per_sc(x: np.ndarray, y: np.ndarray, ids: list[str], width: float = 0.8) -> list[Line]:
    cols = _colors(len(ids))
    return [Line(x, y[:, i], ids[i], cols[i], width) for i in range(len(ids))]


def spec_components(m: SwarmMetrics, n: int, title: str = "") -> LineFigure:
    """Fig. 10 / 31: weakly connected components of the visibility digraph over time."""
    x, xl = time_axis(m.t_s)
    period = float(m.summary["connectivity"]["orbit_period_s"])
    union = ("union of the digraphs over the last orbit" if m.t_s[-1] - m.t_s[0] >= period else
             f"union of the digraphs since the start (run shorter than the {span_text(period)} orbit)")
    return LineFigure([
        Panel([Line(x, m.n_components, "digraph of the step", "C0", 1.0, step=True),
               Line(x, m.n_components_orbit, union, "C2", 0.9, "--", step=True)],
              "weakly connected components", title=title or "Swarm integrity (paper 002 Figs. 10, 31)",
              ylim=(0, max(3, int(m.n_components.max()) + 1)), integer_y=True),
        Panel([Line(x, m.largest, "largest component", "C1", 1.0, step=True)], "largest component [spacecraft]",
              hlines=[(float(n), "k", f"all {n}")], ylim=(0, n + 1), integer_y=True, xlabel=xl),
    ], panel_height_in=2.3)


def _circle_layout(n: int) -> np.ndarray:
    ang = np.pi / 2 - 2 * np.pi * np.arange(n) / n
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


def fig_digraph(truth: TruthArrays, m: SwarmMetrics, row: int, path: Path, label: str) -> str:
    """Figs. 8-9 / 11: the visibility digraph (j -> k: j sees k) in LVLH and as a graph plot."""
    return _save(draw_digraph(truth, m, row, label), path)


def draw_digraph(truth: TruthArrays, m: SwarmMetrics, row: int, label: str):  # type: ignore[no-untyped-def]
    """The matplotlib figure of fig_digraph (not saved)."""
    plt = _plt()
    vis = m.vis[row]
    pos = relative_to_com(truth.position_m[row:row + 1], truth.alive[row:row + 1])[0]
    ids = truth.ids
    n = len(ids)
    comp_colors = _colors(max(1, m.n_components[row]))
    from scipy.sparse.csgraph import connected_components

    _nc, labels = connected_components(vis, directed=True, connection="weak")
    node_c = [comp_colors[lab % len(comp_colors)] for lab in labels]
    fig, ax = plt.subplots(1, 2, figsize=(12, 5.4), gridspec_kw={"width_ratios": [1.6, 1]})
    a = ax[0]
    for j, k in zip(*np.nonzero(vis)):
        a.annotate("", xy=(pos[k, 1], pos[k, 0]), xytext=(pos[j, 1], pos[j, 0]),
                   arrowprops=dict(arrowstyle="->", color="0.5", lw=0.7, ls=":"))
    a.scatter(pos[:, 1], pos[:, 0], c=node_c, s=30, zorder=3, edgecolors="k", linewidths=0.5)
    for i, sid in enumerate(ids):
        a.annotate(sid, (pos[i, 1], pos[i, 0]), fontsize=6, xytext=(2, 3), textcoords="offset points")
    a.set_xlabel("along-track y - y_com [m]")
    a.set_ylabel("radial x - x_com [m]")
    a.set_title("positions (LVLH, centre of mass);\narrow j -> k when j sees k")
    b = ax[1]
    order = np.argsort(truth.position_m[row, :, 1])[::-1]  # leader at the top, then clockwise backwards
    xy = np.empty((n, 2))
    xy[order] = _circle_layout(n)
    for j, k in zip(*np.nonzero(vis)):
        b.annotate("", xy=xy[k], xytext=xy[j], arrowprops=dict(arrowstyle="-|>", color="0.4", lw=0.8,
                                                               shrinkA=7, shrinkB=7))
    b.scatter(xy[:, 0], xy[:, 1], c=node_c, s=160, zorder=3, edgecolors="k", linewidths=0.5)
    for i, sid in enumerate(ids):
        b.text(xy[i, 0] * 1.16, xy[i, 1] * 1.16, sid, ha="center", va="center", fontsize=7)
    b.set_xlim(-1.35, 1.35)
    b.set_ylim(-1.3, 1.3)
    b.set_aspect("equal")
    b.axis("off")
    b.set_title(f"{m.n_components[row]} weak component(s), {int(vis.sum())} edges;\n"
                "nodes ordered by along-track position")
    fig.suptitle(f"Visibility digraph at the {label} (t = {span_text(float(truth.t_s[row]))})")
    fig.tight_layout()
    return fig


_ROE_NAMES = ["a da", "a dl", "a dex", "a dey", "a dix", "a diy"]


def spec_roe_com(truth: TruthArrays, pair: tuple[int, int], fig_no: str) -> LineFigure:
    """Figs. 12-14: ROE of each spacecraft relative to the swarm centre of mass."""
    roe = relative_to_com(truth.roe_m, truth.alive)
    x, xl = time_axis(truth.t_s)
    return LineFigure([Panel(_per_sc(x, roe[:, :, c], truth.ids), f"{_ROE_NAMES[c]} - com [m]",
                             title=f"ROE relative to the swarm centre of mass (paper 002 Fig. {fig_no})" if k == 0 else "",
                             xlabel=xl if k == 1 else "")
                       for k, c in enumerate(pair)])


def spec_separation(m: SwarmMetrics, ids: list[str], field: str, threshold: float, ylabel: str, title: str,
                    extra: str | None = None) -> LineFigure:
    """Figs. 15-17: separation of each spacecraft from its closest visible neighbour."""
    y = getattr(m.closest, field)
    x, xl = time_axis(m.t_s)
    lines = _per_sc(x, y, ids, 0.7)
    lo = float(np.nanmin(y)) if np.isfinite(y).any() else 0.0
    if extra is not None:
        e = getattr(m.closest, extra)
        with np.errstate(all="ignore"):
            emin = np.where(np.isfinite(e).any(axis=1), np.nanmin(np.where(np.isfinite(e), e, np.inf), axis=1), np.nan)
        lines.append(Line(x, emin, "min over spacecraft of a(|dl|-2|de|)", "k", 0.9, ":"))
        if np.isfinite(emin).any():
            lo = min(lo, float(np.nanmin(emin)))
    return LineFigure([Panel(lines, ylabel, title=title, hlines=[(threshold, "r", f"threshold {threshold:g} m")],
                             ylim=(min(0.0, lo), None), shade=_steady_span(m, x), xlabel=xl)], panel_height_in=3.6)


def spec_parallelism(m: SwarmMetrics, ids: list[str]) -> LineFigure:
    """Fig. 18: parallelism |de.di|/(|de||di|) of visible pairs."""
    x, xl = time_axis(m.t_s)
    pp = m.pair_parallelism.reshape(m.t_s.size, -1)
    with np.errstate(all="ignore"):
        has = np.isfinite(pp).any(axis=1)
        lo = np.where(has, np.nanmin(np.where(np.isfinite(pp), pp, np.inf), axis=1), np.nan)
        frac = np.where(has, np.nansum(pp >= PARALLEL_MIN, axis=1) / np.maximum(np.isfinite(pp).sum(axis=1), 1), np.nan)
    return LineFigure([
        Panel(_per_sc(x, m.closest.parallelism, ids, 0.7), "closest visible neighbour",
              title="Parallelism of de and di (paper 002 Fig. 18)", hlines=[(PARALLEL_MIN, "r", "")]),
        Panel([Line(x, lo, "min over visible pairs", "C3"), Line(x, frac, f"fraction of visible pairs >= {PARALLEL_MIN}", "C0")],
              "visible pairs", hlines=[(PARALLEL_MIN, "r", "")], ylim=(-0.02, 1.02), xlabel=xl),
    ])


def spec_accel(m: SwarmMetrics, ids: list[str]) -> LineFigure:
    """Fig. 19: control acceleration of each spacecraft."""
    x, xl = time_axis(m.t_s)
    return LineFigure([Panel(_per_sc(x, m.accel_mps2 * 1e3, ids, 0.6), "|a| [mm/s^2]",
                             title="Control acceleration of each spacecraft (paper 002 Fig. 19)", xlabel=xl)],
                      panel_height_in=3.6)


def spec_dv(m: SwarmMetrics, ids: list[str]) -> LineFigure:
    """Fig. 20: cumulative dV of each spacecraft and of the swarm."""
    x, xl = time_axis(m.t_s)
    return LineFigure([
        Panel(_per_sc(x, m.delta_v_mps, ids), "dV per spacecraft [m/s]", title="Cumulative dV (paper 002 Fig. 20)"),
        Panel([Line(x, m.delta_v_mps.sum(axis=1), "swarm total", "k", 1.0)], "total dV [m/s]",
              shade=_steady_span(m, x), xlabel=xl),
    ])


def spec_along_track(truth: TruthArrays, title: str) -> LineFigure:
    """Figs. 7 / 21: along-track position relative to the swarm centre of mass."""
    pos = relative_to_com(truth.position_m, truth.alive)
    x, xl = time_axis(truth.t_s)
    return LineFigure([Panel(_per_sc(x, pos[:, :, 1] / 1e3, truth.ids), "y - y_com [km]", title=title, xlabel=xl)],
                      panel_height_in=3.6)


def projection_window(truth: TruthArrays, orbits: float = 3.0) -> tuple[float, str]:
    """The trailing window of Fig. 22 (the paper: the last orbits), clipped to the run: (s, label)."""
    period = 2.0 * np.pi / truth.mean_motion_radps
    run_s = float(truth.t_s[-1] - truth.t_s[0])
    used, label = window_text(run_s, orbits * period)
    return used, (label if used >= run_s else f"{label}, {orbits:g} orbits")


def spec_projections(truth: TruthArrays, orbits: float | None = 3.0) -> LineFigure:
    """Fig. 22: cross-track (x-z) and in-orbit (y-x) projections relative to the centre of mass, over
    the last `orbits` orbits (None: the whole run); the window is clipped to the run and named in the titles."""
    pos = relative_to_com(truth.position_m, truth.alive)
    if orbits is None:
        last_s, span = window_text(float(truth.t_s[-1] - truth.t_s[0]), None)
    else:
        last_s, span = projection_window(truth, orbits)
    p = pos[truth.t_s >= truth.t_s[-1] - last_s - 1e-9]
    cols = _colors(truth.n_bodies)
    ids = truth.ids
    cross = [Line(p[:, i, 2], p[:, i, 0], ids[i], cols[i], 0.6) for i in range(len(ids))]
    inorb = [Line(p[:, i, 1], p[:, i, 0], ids[i], cols[i], 0.6, legend=False) for i in range(len(ids))]
    inorb += [Line(p[-1:, i, 1], p[-1:, i, 0], ids[i], cols[i], marker=True, legend=False) for i in range(len(ids))]
    return LineFigure([
        Panel(cross, "radial x - x_com [m]", title=f"Cross-track projection ({span}; paper 002 Fig. 22 upper)",
              xlabel="cross-track z - z_com [m]", equal=True),
        Panel(inorb, "radial x - x_com [m]", title=f"In-orbit projection ({span}; paper 002 Fig. 22 lower), dots at the end",
              xlabel="along-track y - y_com [m]"),
    ], panel_height_in=3.8, sharex=False)


def spec_closest_approach(m: SwarmMetrics) -> LineFigure:
    """Closest approach per step of pairs in visibility and of pairs not in visibility."""
    a = m.approach
    x, xl = time_axis(m.t_s[:-1])
    return LineFigure([Panel([Line(x, a["visible_distance_m"], "pairs in visibility", "C0", 0.7),
                              Line(x, a["hidden_distance_m"], "pairs not in visibility", "C3", 0.7)],
                             "min pair distance [m]", title="Closest approach of any pair in each step (Hermite-interpolated)",
                             hlines=[(D_MIN_TRANS_M, "k", f"d_min_trans = {D_MIN_TRANS_M:g} m")], log_y=True, xlabel=xl)],
                      panel_height_in=3.6)


# --- html -----------------------------------------------------------------------------------------------
def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}" if abs(v) < 1e4 else f"{v:.0f}"
    return html.escape(str(v))


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * x:.1f} %"


def _check(ok: bool) -> str:
    return '<span class="ok">yes</span>' if ok else '<span class="bad">no</span>'


def _headline(summary: dict[str, Any], met: dict[str, Any]) -> list[tuple[str, str]]:
    c, cv, ctl, ca = met["connectivity"], met["closest_visible_steady"], met["control"], met["closest_approach"]
    run_s = met["t_end_s"] - met.get("t_start_s", 0.0)
    _hour_s, hour = window_text(run_s, H)

    def mn(d: dict) -> str:
        return f"min {_fmt(d.get('min'))}, p05 {_fmt(d.get('p05'))}, median {_fmt(d.get('median'))}, " \
               f"{_fmt(100 * d.get('fraction_ge_threshold', float('nan')))} % >= {_fmt(d.get('threshold'))}"

    def ap(d: dict) -> str:
        if d["distance_m"] is None:
            return "none"
        return f"{_fmt(d['distance_m'])} m ({'-'.join(d['pair'])} at t = {span_text(d['t_s'])})"

    return [
        ("run", _fmt(summary.get("run"))),
        ("scenario / controller", f"{_fmt(summary.get('scenario'))} / {_fmt(summary.get('controller'))}"),
        ("spacecraft, duration", f"{summary.get('agents', '?')} spacecraft, {span_text(run_s)} ({met['steps']} steps)"),
        ("always weakly connected (every step)",
         f"{_check(c['always_weakly_connected'])} ({_pct(c['weakly_connected_fraction'])} of the steps; max "
         f"{c['max_components']} components, {c['components_end']} at the end (largest {c['largest_component_end']}); "
         f"first split {'never' if c['first_split_t_s'] is None else span_text(c['first_split_t_s'])})"),
        ("weakly connected over each orbit (union of the last orbit's digraphs)",
         f"{_pct(c.get('orbit_union_weakly_connected_fraction'))} of the steps after the first orbit; "
         f"max {c.get('orbit_union_max_components')} components"),
        (f"along-track to closest visible, steady window t >= {span_text(met['steady_from_s'])} [m]", mn(cv["along_track_m"])),
        ("  orbit-minimum a(|dl|-2|de|) [m]", mn(cv["along_track_orbit_min_m"])),
        ("  radial a|de| [m]", mn(cv["radial_m"])),
        ("  cross-track a|di| [m]", mn(cv["cross_track_m"])),
        ("  parallelism", mn(cv["parallelism"])),
        ("parallelism, all visible pairs, steady", mn(met["visible_pairs_parallelism_steady"])),
        ("total dV [m/s]", f"{_fmt(ctl['delta_v_total_mps'], 4)} (max per spacecraft {_fmt(ctl['delta_v_max_spacecraft_mps'])}; "
                           f"{_fmt(ctl['delta_v_in_steady_window_mps'])} in the steady window, "
                           f"{_fmt(ctl['delta_v_last_hour_mps'])} over the {hour}; 95 % spent by "
                           f"t = {span_text(ctl['t_95pct_delta_v_s'])})"),
        ("max |a| [m/s^2]", _fmt(ctl["accel_max_mps2"])),
        ("closest approach, all pairs", ap(ca["all_pairs"])),
        ("closest approach, pairs in visibility", ap(ca["visible_pairs"])),
        ("closest approach, pairs not in visibility", ap(ca["non_visible_pairs"])),
        ("closest approach in steady window: visible / not visible",
         f"{ap(ca['visible_pairs_steady'])} / {ap(ca['non_visible_pairs_steady'])}"),
    ]


def _camera_for(run_dir: Path, summary: dict[str, Any]) -> CameraGeometry:
    """The camera of a run: from earlier metrics, the configuration the recording carries
    (dashboards/run_config.py), and for recordings older than that the sweep's scenario_doc.json,
    the scenario file of the same name in deploy/scenarios, or else the paper's (500 m, 1080 px,
    f = 1000 px)."""
    cam = summary.get("metrics", {}).get("camera")
    if cam:
        return CameraGeometry(cam["detection_range_m"], int(cam["image_px"]), cam["focal_px"])
    recorded = camera_from_config(run_config(run_dir))
    if recorded is not None:
        return recorded
    doc_path = run_dir / "scenario_doc.json"
    if doc_path.is_file():
        c = json.loads(doc_path.read_text()).get("camera", {})
        return CameraGeometry(c.get("detection_range_m", 500.0), int(c.get("image_px", 1080)), c.get("focal_px", 1000.0))
    src = summary.get("scenario_file")
    path = Path(__file__).resolve().parent.parent / "deploy" / "scenarios" / str(src)
    if src and path.is_file():
        from deploy.scenario import ScenarioError, load_scenario

        try:
            c = load_scenario(path).camera
            return CameraGeometry(c["detection_range_m"], c["image_px"], c["focal_px"])
        except ScenarioError:
            pass
    return CameraGeometry()


def write_report(run_dir: str | Path, *, cam: CameraGeometry | None = None, steady_from_s: float | None = None,
                 projection_orbits: float = 3.0, figures: bool = True, interactive: bool = True,
                 export: tuple[str, ...] = ("svg", "pdf")) -> Path:
    """Metrics into run_dir/summary.json["metrics"] and their time series into
    run_dir/metrics_series.npz; with `figures`, the report site run_dir/report/ (dashboards/site.py):
    index.html and its pages, the figures (PNG, SVG, PDF; Plotly where there are many lines when
    `interactive`; the vector copies of `export`) and the tables of report/data/."""
    from dashboards.figstyle import exporting

    with exporting(export):
        return _write_report(Path(run_dir), cam, steady_from_s, projection_orbits, figures, interactive)


def write_metrics(run_dir: str | Path, truth: TruthArrays, cam: CameraGeometry,
                  steady_from_s: float | None = None) -> Path:
    """What `write_report(..., figures=False)` writes (the metrics into run_dir/summary.json and
    run_dir/metrics_series.npz), from truth arrays the caller already holds (issue 16: a campaign's
    batch run keeps them, deploy/batch.TruthLog) instead of reading run.mcap back."""
    run_dir = Path(run_dir)
    spath = run_dir / "summary.json"
    _write_metrics(run_dir, json.loads(spath.read_text()) if spath.is_file() else {}, truth, cam, steady_from_s)
    return spath


def _write_metrics(run_dir: Path, summary: dict[str, Any], truth: TruthArrays, cam: CameraGeometry,
                   steady_from_s: float | None) -> tuple[SwarmMetrics, dict[str, Any]]:
    m = compute_metrics(truth, cam, steady_from_s)
    met = m.summary
    met["camera"] = {"detection_range_m": cam.detection_range_m, "image_px": cam.image_px, "focal_px": cam.focal_px}
    summary["metrics"] = met
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=1))
    np.savez_compressed(run_dir / SERIES, t_s=m.t_s, n_components=m.n_components, largest=m.largest,
                        n_components_orbit=m.n_components_orbit,
                        delta_v_total_mps=m.delta_v_mps.sum(axis=1))
    return m, met


def _write_report(run_dir: Path, cam: CameraGeometry | None, steady_from_s: float | None, projection_orbits: float,
                  figures: bool, interactive: bool) -> Path:
    from dashboards.frames import metrics_series_frame
    from dashboards.site import figures_of, write_site

    spath = run_dir / "summary.json"
    summary = json.loads(spath.read_text()) if spath.is_file() else {}
    cam = cam or _camera_for(run_dir, summary)
    truth = read_truth(run_dir / "run.mcap", summary.get("run"))
    m, met = _write_metrics(run_dir, summary, truth, cam, steady_from_s)
    if not figures:
        return spath
    out = run_dir / "report"
    out.mkdir(exist_ok=True)
    summary.setdefault("config", run_config(run_dir) or {})
    figs = (_paper002_figures(truth, m, met, out, projection_orbits, interactive)
            if _is_paper002(summary) else [])
    sections = _mission_sections(run_dir, out, summary, truth)
    for s in sections:
        s["figures"] = figures_of(out, s["figures"])
    spath.write_text(json.dumps(summary, indent=1))
    title = f"swarmhil report: {summary.get('scenario', truth.run)}"
    from dashboards.sections.contact import overview_rows

    return write_site(run_dir, out, title, overview_rows(summary) + _headline(summary, met), figs, sections,
                      metrics_series_frame(m),
                      summary["metrics"],
                      intro="<p>Metrics computed from the recorded truth (dashboards/metrics.py); the full numbers are in "
                            "<code>summary.json</code> under <code>metrics</code> and in <a href=\"data.html\">the data "
                            "tables</a>.</p>")


def _paper002_figures(truth: TruthArrays, m: SwarmMetrics, met: dict[str, Any], out: Path,
                      projection_orbits: float | None, interactive: bool = True) -> list:
    """The figures of paper 002 (Figs. 7-22), for runs of its controllers only: many-line figures
    interactive (and static), the digraphs static."""
    from dashboards.site import line_figure, static_figure

    ids = truth.ids
    controlled = met["control"]["delta_v_total_mps"] > 0
    last = len(truth.t_s) - 1

    def lf(spec: LineFigure, png: str, caption: str, many: bool = True):  # noqa: ANN202
        return line_figure(out, spec, png, caption, interactive and many)

    return [
        lf(spec_components(m, len(ids)), "components.png",
           "Weakly connected components of the visibility digraph and size of the largest (paper Figs. 10, 31).",
           many=False),
        static_figure(out, fig_digraph(truth, m, 0, out / "digraph_start.png", "start"),
                      "Visibility digraph at the start (paper Figs. 8-9)."),
        static_figure(out, fig_digraph(truth, m, last, out / "digraph_end.png", "end"),
                      "Visibility digraph at the end (paper Fig. 11)."),
        lf(spec_roe_com(truth, (0, 1), "12"), "roe_a_l.png", "a da and a dl relative to the centre of mass (paper Fig. 12)."),
        lf(spec_roe_com(truth, (2, 3), "13"), "roe_e.png", "a dex, a dey relative to the centre of mass (paper Fig. 13)."),
        lf(spec_roe_com(truth, (4, 5), "14"), "roe_i.png", "a dix, a diy relative to the centre of mass (paper Fig. 14)."),
        lf(spec_separation(m, ids, "along_track_m", D_MIN_M, "|y_k - y_j| [m]",
                           "Along-track distance to the closest visible neighbour (paper Fig. 15)", extra="along_min_m"),
           "sep_along.png",
           f"Instantaneous along-track separation from each spacecraft to its closest visible neighbour; red: d_min = "
           f"{D_MIN_M:g} m; dotted: the smallest orbit-minimum a(|dl|-2|de|) of section 3.3. Grey: steady window."),
        lf(spec_separation(m, ids, "cross_m", D_MIN_TRANS_M, "a|di_jk| [m]",
                           "Out-of-plane size of the relative ellipse, closest visible neighbour (paper Fig. 16)"),
           "sep_cross.png", f"Red: d_min_trans = {D_MIN_TRANS_M:g} m."),
        lf(spec_separation(m, ids, "radial_m", D_MIN_TRANS_M, "a|de_jk| [m]",
                           "Radial size of the relative ellipse, closest visible neighbour (paper Fig. 17)"),
           "sep_radial.png", f"Red: d_min_trans = {D_MIN_TRANS_M:g} m."),
        lf(spec_parallelism(m, ids), "parallelism.png", "Parallelism |de.di|/(|de||di|) (paper Fig. 18); red: 0.8."),
        lf(spec_accel(m, ids), "accel.png", "Commanded acceleration after the actuator limit (paper Fig. 19)."),
        lf(spec_dv(m, ids), "dv.png", "Cumulative dV (paper Fig. 20); grey: steady window."),
        lf(spec_along_track(truth, "Along-track position relative to the centre of mass (paper Fig. 21)" if controlled
                            else "Along-track position of the uncontrolled swarm (paper Fig. 7)"), "along_track.png",
           "Along-track position relative to the swarm centre of mass."),
        lf(spec_projections(truth, projection_orbits), "projections.png",
           "Cross-track and in-orbit projections of the trajectories relative to the centre of mass (paper Fig. 22)."),
        lf(spec_closest_approach(m), "closest_approach.png",
           "Minimum distance over each step of pairs in visibility (either direction) and of pairs not in "
           "visibility: the paper's safety claim covers visible pairs only.", many=False),
    ]


PAPER002_CONTROLLERS = {"null", "drift-null", "sabatini"}


def _is_paper002(summary: dict[str, Any]) -> bool:
    from dashboards.sections import controllers_of

    cfg = summary.get("config") or {}
    return not cfg or controllers_of(cfg) <= PAPER002_CONTROLLERS


def _mission_sections(run_dir: Path, out: Path, summary: dict[str, Any], truth: TruthArrays) -> list[dict[str, Any]]:
    """Run every registered report section that applies to this run (dashboards/sections/): metrics
    into summary["metrics"][name]; returns {anchor, title, html, figures: [(PNG, caption)]} per section."""
    from dashboards.sections import SectionContext, sections_for

    cfg = summary["config"]  # write_report filled it from the recording
    blocks = []
    for name, fn in sections_for(cfg):
        res = fn(SectionContext(run_dir, run_dir / "run.mcap", out, summary, cfg, truth))
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
        table += "<tr>" + "".join(f"<td>{_fmt(r.get(c))}</td>" for c in cols) + f"<td>{link}</td></tr>"
    table += "</table>"
    from dashboards.site import figures_of, render

    render("page.html", out / "index.html", title=f"swarmhil sweep: {param}", head=head,
           figures=figures_of(out, figs), intro=table)
    return out / "index.html"


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)
