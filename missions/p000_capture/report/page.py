"""Paper 000's report, page: the section `p000-capture` (its figures and table) for the runs flown
with `p000-capture`, and the registration of the room's landmark kind with the viewer (its sensor
cone and returns, dashboards/rerun_bodies.py).
"""
from __future__ import annotations

import html

from swarmhil.dashboards.rerun_bodies import register_landmark_kind
from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section, uses_controller
from swarmhil.missions.p000_capture.contract import CONTROLLER, LANDMARK_IDS, LANDMARKS_BODY_M, SENSING_KIND
from swarmhil.missions.p000_capture.report.analysis import compute, window_label
from swarmhil.missions.p000_capture.report.figures import (
    fig_axes,
    fig_centroid,
    fig_messages,
    fig_pairs,
    fig_paths,
    fig_pointing,
    fig_surface,
    fig_triggers,
)

register_landmark_kind(SENSING_KIND, LANDMARKS_BODY_M, LANDMARK_IDS)  # the viewer's sensor cone and returns


def _table(rows: list[tuple[str, str]]) -> str:
    return "<table>" + "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows) + "</table>"


@register_section("p000-capture", applies=lambda cfg: uses_controller(cfg, CONTROLLER))
def capture(ctx: SectionContext) -> SectionResult:
    a = compute(ctx)
    met, rec, ids, run, t, pos, dt, axes, r_buffer = a.met, a.rec, a.ids, a.run, a.t, a.pos, a.dt, a.axes, a.r_buffer
    rows, sd, s_arg, pair, entry, types, dv = a.rows, a.sd, a.s_arg, a.pair, a.entry, a.types, a.dv
    point, rate, est_axes, c_err, has_est = a.point, a.rate, a.est_axes, a.c_err, a.has_est

    out = ctx.out
    figs = [
        (fig_paths(pos, rec, axes, r_buffer, ids, run, t, out / "p000_paths3d.png"),
         "Paths relative to the target's centre (CW axes) around the true ellipsoid at the last step and "
         "its buffer shell (approx.); o start, square end."),
        (fig_surface(t[rows], sd, entry, r_buffer, ids, run, out / "p000_surface.png"),
         "Signed distance of each agent to the TRUE target surface (room's closest-point routine; negative "
         "inside), with R_buffer and the chase entries."),
        (fig_pairs(t, pair, ids, run, out / "p000_pairs.png"),
         "Distance of each agent to its nearest neighbour, and the swarm minimum."),
        (fig_messages(rec.tx, dt, float(t[-1]), ids, types, run, out / "p000_messages.png"),
         "Cumulative packets sent per agent and message type (the recorded isl/tx topics)."),
    ]
    figs.append((fig_triggers(rec.tx, dt, float(t[-1]), ids, run, out / "p000_triggers.png"),
                 "Trigger instants: each agent's p000-state broadcasts (event trigger eq. 28, forced events, or "
                 "the baseline schedule)."))
    if point is not None:
        figs.append((fig_pointing(t, point, rate, ids, run, out / "p000_pointing.png"),
                     "Attitude errors: angle between each agent's sensor boresight (body +x) and the line of sight "
                     "to the TRUE centroid; body rate magnitude."))
    if has_est.any():
        figs.append((fig_axes(t, est_axes, axes, ids, run, out / "p000_axes.png"),
                     "Figs. 7/12: each agent's sorted semi-axes estimate (from its telemetry) against the truth "
                     "(dashed)."))
        figs.append((fig_centroid(t, c_err, ids, run, out / "p000_centroid.png"),
                     "Distance of each agent's centroid estimate (telemetry) to the TRUE target centre."))
    lt = met["link"]["per_type"]
    table = _table([
        ("window", window_label(t)),
        ("agents in chase/dock at the end", f"{met['in_chase_at_end']} of {len(ids)}"),
        ("chase entries", ", ".join(f"{n} {x:g} s" for n, x in met["chase_entry_s"].items()) or "none"),
        ("min signed distance to the true surface", f"{met['min_surface_m']:.3g} m ({ids[s_arg[1]]}, "
                                                    f"t = {met['min_surface_at']['t_s']:.1f} s)"),
        ("final signed distance", f"{sd[-1].min():.3g}-{sd[-1].max():.3g} m"),
        ("min pair distance", f"{met['min_pair_m']:.3g} m ({' - '.join(met['min_pair_at']['pair'])}, "
                              f"t = {met['min_pair_at']['t_s']:.1f} s)"),
        ("dV per agent", f"{dv.min():.4g}-{dv.max():.4g} m/s (total {dv.sum():.4g} m/s)"),
        *[(f"{ty} sent / delivered", f"{c['tx_messages']} packets, {c['tx_payload_bytes']} B / "
                                     f"{c['rx_messages']} packets, {c['rx_payload_bytes']} B")
          for ty, c in lt.items()],
        ("state packets vs every step / vs 1 Hz of the chase time",
         f"{met['every_step_ratio']:.3g} / {met['hz1_ratio']:.3g}"),
        *([("final pointing error (worst)", f"{met['pointing_final_max_deg']:.3g} deg")] if point is not None else []),
        *([("final sorted semi-axes error (worst) / within 2 %",
            f"{100 * met['axes_final_rel_err_max']:.3g} % / {met['axes_within_2pct']} of {int(has_est.sum())}"),
           ("final centroid error (worst)", f"{met['centroid_final_err_max_m']:.3g} m")] if has_est.any() else []),
    ])
    return SectionResult(title="Paper 000: event-triggered capture of a tumbling target", metrics=met,
                         figures=figs, html=table)
