"""Paper 004's report, analysis: the tracking errors, control effort and Δv of the servicers from
the truth, the section's metrics (`compute`) and its error metric for the faults section
(`largest_tracking_error`). No figures, no pages. The scalar figures (`servicing_figures`,
`first_time_below`, `tracking_errors`) are shared with tests/missions/test_p004_stack.py, which
computes them from its own reading of the MCAP.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarmhil.dashboards.sections import ErrorSeries, SectionContext
from swarmhil.missions.p004_lbdnn.report.read import defunct_id, mission_of, read_body, servicers

STEADY_FROM_S = 200.0     # §6: "after ≈ 200 s" the errors are a few metres
TRACK_LEVEL_M = 10.0      # time to below 10 m


# --- the figures of a run (shared with tests/missions/test_p004_stack.py) ----------------------------
def first_time_below(t: np.ndarray, y: np.ndarray, level: float) -> float:
    """The first time from which y stays below `level` to the end (inf: it is not below at the end)."""
    above = np.nonzero(y >= level)[0]
    if above.size == 0:
        return float(t[0])
    return float(t[above[-1] + 1]) if above[-1] + 1 < t.size else float("inf")


def tracking_errors(defunct_pos: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """‖e_i‖ = ‖q0 − q_i‖, (K, N) from the defunct craft's (K, 3) and the servicers' (K, N, 3)
    positions in any one frame."""
    return np.linalg.norm(defunct_pos[:, None, :] - pos, axis=2)


def servicing_figures(t: np.ndarray, e: np.ndarray, u: np.ndarray, delta_v_end: np.ndarray) -> dict[str, Any]:
    """The paper's figures: e (K, N) tracking error norms at t (K,), u (K-1 or K, N) command norms
    (row k applied over [t_k, t_k+1)), delta_v_end (N,) the cumulative Δv at the end."""
    out: dict[str, Any] = {
        "t": t, "e_norm": e, "u_norm": u,
        "e_start_min_m": float(e[0].min()), "e_end_max_m": float(e[-1].max()),
        "e_end_mean_m": float(e[-1].mean()),
        "t_e_below_10m_s": max(first_time_below(t, e[:, i], TRACK_LEVEL_M) for i in range(e.shape[1])),
        "u_peak_mps2": float(u.max()), "delta_v_max_mps": float(np.max(delta_v_end))}
    if t[-1] >= STEADY_FROM_S:
        out["e_mean_after_200s_m"] = float(e[t >= STEADY_FROM_S].mean())
        out["e_max_after_200s_m"] = float(e[t >= STEADY_FROM_S].max())
    return out


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def compute(ctx: SectionContext) -> tuple[dict[str, Any], dict[str, Any]]:
    """(metrics for summary.json, arrays for the figures)."""
    truth, cfg = ctx.truth, ctx.config
    dfid = defunct_id(cfg)
    body = read_body(ctx.mcap, dfid, truth.run)
    missing = [int(k) for k in truth.step if int(k) not in body]
    if missing:
        raise ValueError(f"{dfid!r} is missing from the Truth messages of steps {missing[:5]}...")
    q0 = np.array([body[int(k)][0] for k in truth.step])
    sv = servicers(cfg, truth.ids)
    cols = [truth.ids.index(s) for s in sv]
    t = truth.t_s
    pos = truth.position_m[:, cols]
    e = tracking_errors(q0, pos)
    u = np.linalg.norm(truth.accel_mps2[:-1, cols], axis=2)        # over [t_k, t_k+1), k < K-1
    dv = truth.delta_v_mps[:, cols]
    fig = servicing_figures(t, e, u, dv[-1])
    steady = t >= STEADY_FROM_S
    u_steady = t[:-1] >= STEADY_FROM_S
    per = {}
    for j, s in enumerate(sv):
        per[s] = {
            "e_start_m": float(e[0, j]), "e_end_m": float(e[-1, j]),
            "e_mean_after_200s_m": float(e[steady, j].mean()) if steady.any() else None,
            "e_max_after_200s_m": float(e[steady, j].max()) if steady.any() else None,
            "t_e_below_10m_s": _finite(first_time_below(t, e[:, j], TRACK_LEVEL_M)),
            "u_peak_mps2": float(u[:, j].max()),
            "u_mean_after_200s_mps2": float(u[u_steady, j].mean()) if u_steady.any() else None,
            "delta_v_mps": float(dv[-1, j]),
        }
    duration = float(t[-1] - t[0])
    tot = (ctx.summary.get("channel") or {}).get("totals") or {}
    link = {k: int(tot[k]) for k in ("tx_messages", "tx_payload_bytes", "rx_messages", "rx_payload_bytes",
                                      "dropped_range", "dropped_occulted", "dropped_lost", "dropped_queue")
            if k in tot}
    if "tx_payload_bytes" in tot and duration > 0 and sv:
        link["tx_bytes_per_s_per_servicer"] = float(tot["tx_payload_bytes"]) / duration / len(sv)
    if tot.get("tx_messages"):
        link["bytes_per_message"] = float(tot["tx_payload_bytes"]) / float(tot["tx_messages"])
    mission = mission_of(cfg)
    met: dict[str, Any] = {
        "defunct_id": dfid, "servicers": sv, "duration_s": duration,
        "steady_from_s": STEADY_FROM_S, "track_level_m": TRACK_LEVEL_M,
        "graph_edges": [list(ed) for ed in mission.edges],
        "b": {s: int(mission.b[s]) for s in mission.servicers},
        "c_rows": {s: int(np.atleast_2d(mission.c_matrices[s]).shape[0]) for s in mission.servicers},
        "lambda_min_h": mission.lambda_min_h(),
        "use_network": bool(mission.use_network),
        "e_start_min_m": fig["e_start_min_m"], "e_end_max_m": fig["e_end_max_m"],
        "e_end_mean_m": fig["e_end_mean_m"],
        "e_mean_after_200s_m": fig.get("e_mean_after_200s_m"),
        "e_max_after_200s_m": fig.get("e_max_after_200s_m"),
        "t_all_below_10m_s": _finite(fig["t_e_below_10m_s"]),
        "u_peak_mps2": fig["u_peak_mps2"],
        "u_mean_after_200s_mps2": float(u[u_steady].mean()) if u_steady.any() else None,
        "delta_v_max_mps": fig["delta_v_max_mps"],
        "delta_v_total_mps": float(dv[-1].sum()),
        "per_servicer": per,
        "link": link,
    }
    arrays = {"t": t, "e": e, "u": u, "dv": dv, "rel": pos - q0[:, None, :], "ids": sv}
    return met, arrays


def largest_tracking_error(ctx: SectionContext) -> ErrorSeries:
    """max_i ‖q0 − q_i‖ over the servicers per step (§6's tracking error, eq. (5)): the faults
    section's per-mission excursion."""
    truth, cfg = ctx.truth, ctx.config
    body = read_body(ctx.mcap, defunct_id(cfg), truth.run)
    keep = np.array([int(k) in body for k in truth.step])
    q0 = np.array([body[int(k)][0] for k in truth.step if int(k) in body]).reshape(-1, 3)
    cols = [truth.ids.index(s) for s in servicers(cfg, truth.ids)]
    e = tracking_errors(q0, truth.position_m[keep][:, cols])
    return ErrorSeries("largest servicer tracking error", "m", truth.t_s[keep], e.max(axis=1))
