"""Paper 002's report, page: the section `p002-swarm` (its metrics table and figures), registered
for the runs its metrics hook covers (metrics.py `applies`). The numbers are the hook's, in
summary.json["metrics"]; the figures are figures.py's, each with its caption here.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from swarmhil.dashboards.figstyle import LineFigure, span_text
from swarmhil.dashboards.kit import approach, check, fmt, head_table, line_figure, pct, static_figure
from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section
from swarmhil.dashboards.truth_io import TruthArrays
from swarmhil.missions.p002_sabatini.contract import D_MIN_M, D_MIN_TRANS_M
from swarmhil.missions.p002_sabatini.report.figures import (
    fig_digraph,
    spec_accel,
    spec_along_track,
    spec_closest_approach,
    spec_components,
    spec_dv,
    spec_parallelism,
    spec_projections,
    spec_roe_com,
    spec_separation,
)
from swarmhil.missions.p002_sabatini.report.metrics import NAME, SwarmGraphMetrics, applies


def _paper002_figures(truth: TruthArrays, m: SwarmGraphMetrics, met: dict[str, Any], out: Path,
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
    figs = _paper002_figures(ctx.truth, ctx.swarm.missions[NAME].detail, met, Path(ctx.out), ctx.projection_orbits, ctx.interactive)
    return SectionResult(title="Paper 002: behavioural swarm keeping", figures=figs,
                         html=head_table(metric_rows(met)))
