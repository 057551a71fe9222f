"""Paper 002's report section (behavioural swarm keeping, Sabatini et al.): its metrics table and
Figs. 7-22, for runs flown only with its controllers (`null`, `drift-null`, `sabatini`) and for
recordings that carry no configuration (older runs, all of paper 002). Registered as `p002-swarm`
(dashboards/sections/); imports its contract and the report kit, never its flight software.

The numbers are the swarm metrics of dashboards/metrics.py, which `write_report` keeps where they
have always been (summary.json["metrics"]: `connectivity`, `closest_visible_steady`, ...); this
section only shows them (issue 25: the overview of every report is mission-neutral, paper 002's ROE
metrics are paper 002's). Figures with one line per spacecraft are LineFigure specs
(dashboards/figstyle.py): drawn static (PNG, SVG, PDF) and interactive (Plotly,
dashboards/interactive.py) from the same data.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.figstyle import Line, LineFigure, Panel, span_text, time_axis, window_text
from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.kit import approach, check, fmt, head_table, line_figure, pct, static_figure
from swarmhil.dashboards.metrics import SwarmMetrics, relative_to_com
from swarmhil.dashboards.sections import SectionContext, SectionResult, controllers_of, register_section
from swarmhil.dashboards.truth_io import TruthArrays
from swarmhil.missions.p002_sabatini.contract import CONTROLLER, D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN
from swarmhil.plant.sensors import weak_components

NAME = "p002-swarm"
PAPER002_CONTROLLERS = {"null", "drift-null", CONTROLLER}  # its law and the baselines of its Figs. 7-9


def applies(config: dict[str, Any]) -> bool:
    """Runs flown with paper 002's controllers only, and recordings without a configuration."""
    return not config or controllers_of(config) <= PAPER002_CONTROLLERS


# --- figures --------------------------------------------------------------------------------------------
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
    labels = weak_components(vis[None])[1][0]  # (scipy's connected_components numbering)
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


def _paper002_figures(truth: TruthArrays, m: SwarmMetrics, met: dict[str, Any], out: Path,
                      projection_orbits: float | None, interactive: bool = True) -> list:
    """The figures of paper 002 (Figs. 7-22), for runs of its controllers only: many-line figures
    interactive (and static), the digraphs static."""
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


# --- the table ---------------------------------------------------------------------------------------------
def metric_rows(met: dict[str, Any]) -> list[tuple[str, str]]:
    """Paper 002's metrics of a run (summary.json["metrics"]) as (name, cell HTML) rows: swarm
    integrity, separations from the closest visible neighbour in the steady window (sections 3.2-3.3),
    parallelism, dV in the steady window and the closest approach split by visibility."""
    c, cv, ctl, ca = met["connectivity"], met["closest_visible_steady"], met["control"], met["closest_approach"]

    def mn(d: dict) -> str:
        return f"min {fmt(d.get('min'))}, p05 {fmt(d.get('p05'))}, median {fmt(d.get('median'))}, " \
               f"{fmt(100 * d.get('fraction_ge_threshold', float('nan')))} % >= {fmt(d.get('threshold'))}"

    return [
        ("always weakly connected (every step)",
         f"{check(c['always_weakly_connected'])} ({pct(c['weakly_connected_fraction'])} of the steps; max "
         f"{c['max_components']} components, {c['components_end']} at the end (largest {c['largest_component_end']}); "
         f"first split {'never' if c['first_split_t_s'] is None else span_text(c['first_split_t_s'])})"),
        ("weakly connected over each orbit (union of the last orbit's digraphs)",
         f"{pct(c.get('orbit_union_weakly_connected_fraction'))} of the steps after the first orbit; "
         f"max {c.get('orbit_union_max_components')} components"),
        (f"along-track to closest visible, steady window t >= {span_text(met['steady_from_s'])} [m]", mn(cv["along_track_m"])),
        ("  orbit-minimum a(|dl|-2|de|) [m]", mn(cv["along_track_orbit_min_m"])),
        ("  radial a|de| [m]", mn(cv["radial_m"])),
        ("  cross-track a|di| [m]", mn(cv["cross_track_m"])),
        ("  parallelism", mn(cv["parallelism"])),
        ("parallelism, all visible pairs, steady", mn(met["visible_pairs_parallelism_steady"])),
        ("dV in the steady window [m/s]", fmt(ctl["delta_v_in_steady_window_mps"])),
        ("closest approach, pairs in visibility", approach(ca["visible_pairs"])),
        ("closest approach, pairs not in visibility", approach(ca["non_visible_pairs"])),
        ("closest approach in steady window: visible / not visible",
         f"{approach(ca['visible_pairs_steady'])} / {approach(ca['non_visible_pairs_steady'])}"),
    ]


@register_section(NAME, applies=applies)
def swarm_keeping(ctx: SectionContext) -> SectionResult:
    """The table and the figures; the metrics stay in summary.json["metrics"] (no section entry)."""
    met = ctx.summary["metrics"]
    figs = _paper002_figures(ctx.truth, ctx.swarm, met, Path(ctx.out), ctx.projection_orbits, ctx.interactive)
    return SectionResult(title="Paper 002: behavioural swarm keeping", figures=figs,
                         html=head_table(metric_rows(met)))
