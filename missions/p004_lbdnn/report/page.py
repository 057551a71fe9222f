"""Paper 004's report, page: the section `p004-servicing` (its table and figures) and the
registrations (the section and its error metric) for the runs flown with `p004-lbdnn`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from swarmhil.dashboards.sections import SectionContext, SectionResult, register_error_metric, register_section, uses_controller
from swarmhil.missions.p004_lbdnn.contract import CONTROLLER
from swarmhil.missions.p004_lbdnn.report.analysis import TRACK_LEVEL_M, compute, largest_tracking_error
from swarmhil.missions.p004_lbdnn.report.figures import fig_effort, fig_paths, fig_tracking

NAME = "p004-servicing"

register_error_metric(NAME, applies=lambda cfg: uses_controller(cfg, CONTROLLER))(largest_tracking_error)


def _table(met: dict[str, Any]) -> str:
    def f(v: Any, d: int = 3) -> str:
        return "–" if v is None else f"{v:.{d}g}"

    rows = "".join(
        f"<tr><td>{s}</td><td>{f(p['e_start_m'], 4)}</td><td>{f(p['e_end_m'])}</td>"
        f"<td>{f(p['e_mean_after_200s_m'])}</td><td>{f(p['e_max_after_200s_m'])}</td>"
        f"<td>{f(p['t_e_below_10m_s'], 4)}</td><td>{f(p['u_peak_mps2'])}</td>"
        f"<td>{f(p['u_mean_after_200s_mps2'])}</td><td>{f(p['delta_v_mps'], 4)}</td></tr>"
        for s, p in met["per_servicer"].items())
    link = met["link"]
    bps = link.get("tx_bytes_per_s_per_servicer")
    return ("<table><tr><th>servicer</th><th>‖e‖ start [m]</th><th>‖e‖ end [m]</th>"
            "<th>mean ‖e‖ after 200 s [m]</th><th>max ‖e‖ after 200 s [m]</th><th>below 10 m from [s]</th>"
            "<th>peak ‖u‖ [m/s²]</th><th>mean ‖u‖ after 200 s [m/s²]</th><th>Δv [m/s]</th></tr>"
            f"{rows}</table><p>λ<sub>min</sub>(H) = {met['lambda_min_h']:.4g} (graph "
            f"{', '.join('-'.join(e) for e in met['graph_edges'])}); all below {TRACK_LEVEL_M:g} m from "
            f"{f(met['t_all_below_10m_s'], 4)} s; link: {link.get('tx_messages', 0)} messages, "
            f"{link.get('tx_payload_bytes', 0)} B sent"
            + (f" ({bps:.0f} B/s per servicer)" if bps is not None else "") + "</p>")


@register_section(NAME, applies=lambda cfg: uses_controller(cfg, CONTROLLER))
def servicing(ctx: SectionContext) -> SectionResult:
    met, arrays = compute(ctx)
    out = Path(ctx.out)
    figs = [
        (fig_tracking(arrays, met, out / "p004_tracking.png"),
         "Tracking errors ‖e_i‖ = ‖q0 − q_i‖ from the recorded truth (paper Fig. 4); red: 10 m; grey: the window "
         "of the lower panel."),
        (fig_effort(arrays, met, out / "p004_effort.png"),
         "Commanded acceleration ‖u_i‖ after the actuator limit and the cumulative Δv (not a figure of the paper). "
         "Fig. 3 (‖ζ̃_i‖) needs the observers' state, which the truth does not carry."),
        (fig_paths(arrays, met, out / "p004_paths.png"),
         "Paths of the servicers relative to the defunct craft in the scenario frame (the defunct craft's LVLH "
         "for servicing-6): 3D over the first 60 s like the paper's Fig. 2 (which is inertial), planar over the run."),
    ]
    return SectionResult(title="Paper 004: servicers converging on the defunct craft", metrics=met,
                         figures=figs, html=_table(met))
