"""Paper 000's report, analysis: pure functions over the arrays of the truth and of read.py
(signed distances to the TRUE target surface with the room's closest-point routine,
missions/p000_capture/contract.py; pair distances, chase entries, the link's counters per type,
pointing, the agents' estimate errors, settle times) and the section's metrics (`compute`). No
figures, no pages. The pure functions (`surface_distance`, `chase_entry`, `link_by_type`,
`pair_distance`) are also what tests/missions/test_p000_stack.py computes its figures with, and
sweep.py its tables.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmhil.dashboards.sections import SectionContext
from swarmhil.missions.p000_capture.contract import Ellipsoid, dcm, signed_distance
from swarmhil.missions.p000_capture.report.read import CaptureRecording, capture_params, read_capture, target_axes

MAX_SURFACE_ROWS = 2000  # signed distance on at most this many recorded steps (always the last)


def surface_rows(k: int, max_rows: int = MAX_SURFACE_ROWS) -> np.ndarray:
    """The recorded rows the signed distance is evaluated on: every `stride`-th and the last."""
    stride = max(1, math.ceil(k / max_rows))
    return np.unique(np.r_[np.arange(0, k, stride), k - 1])


def surface_distance(pos: np.ndarray, target_pos: np.ndarray, target_q: np.ndarray, axes: np.ndarray,
                     rows: np.ndarray | None = None) -> np.ndarray:
    """(len(rows), N) signed distance of every spacecraft to the TRUE target surface (negative inside),
    with the room's closest-point routine."""
    rows = np.arange(len(pos)) if rows is None else rows
    out = np.empty((len(rows), pos.shape[1]))
    for r, k in enumerate(rows):
        ell = Ellipsoid(target_pos[k], dcm(target_q[k]), axes)
        for i in range(pos.shape[1]):
            out[r, i] = signed_distance(ell, pos[k, i])
    return out


def pair_distance(pos: np.ndarray) -> np.ndarray:
    """(K, N, N) distances between spacecraft, +inf on the diagonal."""
    n = pos.shape[1]
    return np.linalg.norm(pos[:, :, None] - pos[:, None], axis=3) + np.diag(np.full(n, np.inf))[None]


def chase_entry(modes: dict[str, dict[int, str]], dt_s: float) -> tuple[dict[str, float], int]:
    """({id: time of the first step out of "search"}, agent-steps spent in chase or dock)."""
    entry, chase_steps = {}, 0
    for sid, m in modes.items():
        out = [k for k in sorted(m) if m[k] != "search"]
        if out:
            entry[sid] = round(out[0] * dt_s, 2)
        chase_steps += len(out)
    return entry, chase_steps


def link_by_type(links: list[list], columns: list[str] | None = None) -> dict[str, dict[str, dict[str, int]]]:
    """The channel's counters per message type and per sending agent: {type: {src: {tx_messages,
    tx_payload_bytes, tx_wire_bytes, rx_messages, rx_payload_bytes, dropped_range}}}. Tx rows are the
    `dst = "*"` ones; the other rows are per receiver (delivered or dropped)."""
    cols = columns or ["src", "dst", "type", "messages", "payload_bytes", "wire_bytes", "dropped_range"]
    out: dict[str, dict[str, dict[str, int]]] = {}
    for row in links:
        r = dict(zip(cols, row))
        c = out.setdefault(r["type"], {}).setdefault(r["src"], {
            "tx_messages": 0, "tx_payload_bytes": 0, "tx_wire_bytes": 0, "rx_messages": 0,
            "rx_payload_bytes": 0, "dropped_range": 0})
        if r["dst"] == "*":
            c["tx_messages"] += int(r["messages"])
            c["tx_payload_bytes"] += int(r["payload_bytes"])
            c["tx_wire_bytes"] += int(r.get("wire_bytes", 0))
        else:
            c["rx_messages"] += int(r["messages"])
            c["rx_payload_bytes"] += int(r["payload_bytes"])
            c["dropped_range"] += int(r.get("dropped_range", 0))
    return out


def pointing_error_deg(pos: np.ndarray, q_inertial: np.ndarray, target_pos: np.ndarray, t_s: np.ndarray,
                       n_radps: float) -> np.ndarray:
    """(K, N) angle between each body's +x boresight and the line of sight to the TRUE centroid. The
    plant's attitude is body -> inertial (aligned with CW at t = 0); the CW frame has turned n t."""
    w, x, y, z = (q_inertial[..., j] for j in range(4))
    bore_i = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], axis=-1)  # R e_x
    c, s = np.cos(n_radps * t_s)[:, None], np.sin(n_radps * t_s)[:, None]
    bore = np.stack([c * bore_i[..., 0] + s * bore_i[..., 1], -s * bore_i[..., 0] + c * bore_i[..., 1],
                     bore_i[..., 2]], axis=-1)  # R_z(-n t) R e_x
    los = target_pos[:, None, :] - pos
    cosang = np.einsum("kni,kni->kn", bore, los) / (np.linalg.norm(bore, axis=2) * np.linalg.norm(los, axis=2))
    return np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))


def axes_error(est_axes: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(K, N) worst relative error of the agents' SORTED semi-axes estimates against the sorted truth
    (the target's axes are body axes of a tumbling body: only the sorted set is comparable); NaN where
    an agent had no estimate."""
    a = np.sort(np.asarray(axes, dtype=float))
    return np.max(np.abs(est_axes - a) / a, axis=-1)


def centroid_error(est_centre: np.ndarray, target_pos: np.ndarray) -> np.ndarray:
    """(K, N) distance of each agent's centroid estimate to the TRUE centre at the same step."""
    return np.linalg.norm(est_centre - target_pos[:, None, :], axis=-1)


def last_finite(x: np.ndarray) -> np.ndarray:
    """(N, ...) each column's value at its last row where it is finite (NaN if never)."""
    ok = np.isfinite(x.reshape(x.shape[0], x.shape[1], -1)).all(axis=-1)  # (K, N)
    out = np.full(x.shape[1:], np.nan)
    for j in range(x.shape[1]):
        rows = np.flatnonzero(ok[:, j])
        if len(rows):
            out[j] = x[rows[-1], j]
    return out


def settle_time(t: np.ndarray, err: np.ndarray, tol: float) -> list[float | None]:
    """Per column: the first time after which err stays below tol to the end (None: never settles)."""
    out: list[float | None] = []
    for j in range(err.shape[1]):
        above = np.flatnonzero(~(err[:, j] < tol))
        out.append(float(t[0]) if not len(above) else (float(t[above[-1] + 1]) if above[-1] + 1 < len(t) else None))
    return out



def window_label(t: np.ndarray) -> str:
    """The run's time window, for titles and the table."""
    return f"t = {t[0]:.1f}-{t[-1]:.1f} s"


@dataclass
class CaptureAnalysis:
    """The section's metrics (summary.json["metrics"]["p000-capture"]) and the arrays its figures
    and table are drawn from (rows of `sd` are the recorded rows `rows`)."""

    met: dict[str, Any]
    rec: CaptureRecording
    ids: list[str]
    run: str
    t: np.ndarray                 # (K,) [s]
    pos: np.ndarray               # (K, N, 3) CW frame
    dt: float                     # step [s]
    axes: np.ndarray              # (3,) the target's semi-axes
    r_buffer: float
    rows: np.ndarray              # the rows the signed distance is evaluated on
    sd: np.ndarray                # (len(rows), N) signed distance to the TRUE surface
    s_arg: tuple                  # (row of sd, agent) of its minimum
    pair: np.ndarray              # (K, N, N) pair distances
    entry: dict[str, float]       # id -> chase entry time [s]
    types: list[str]              # message types of the link
    point: np.ndarray | None      # (K, N) pointing error [deg] (None: attitudes not flown)
    rate: np.ndarray | None       # (K, N, 3) body rates (None: not flown)
    est_axes: np.ndarray          # (K, N, 3) the agents' sorted semi-axes estimates (NaN: none)
    c_err: np.ndarray             # (K, N) centroid error of the agents' estimates
    has_est: np.ndarray           # (N,) bool: the agent had an estimate
    dv: np.ndarray                # (N,) cumulative dV at the end


def compute(ctx: SectionContext) -> CaptureAnalysis:
    """The section's metrics and arrays from the truth, the recording and the configuration."""
    tr = ctx.truth
    ids = list(tr.ids)
    run = str(ctx.summary.get("run") or tr.run)
    rec = read_capture(ctx.mcap, ids, ctx.summary.get("run"))
    if not np.array_equal(rec.steps, tr.step):
        raise ValueError("the target's truth rows do not match the spacecraft's")
    t, pos = tr.t_s, tr.position_m
    dt = float(ctx.summary.get("step_s") or ((ctx.config.get("run") or {}).get("step_s")) or np.diff(t).min())
    axes = target_axes(ctx.config)
    r_buffer = float(capture_params(ctx.config, ids[0]).r_buffer_m)

    rows = surface_rows(len(t))
    sd = surface_distance(pos, rec.target_pos, rec.target_q, axes, rows)
    pair = pair_distance(pos)
    p_arg = np.unravel_index(int(np.argmin(pair)), pair.shape)
    s_arg = np.unravel_index(int(np.argmin(sd)), sd.shape)
    entry, chase_steps = chase_entry(rec.modes, dt)
    last_mode = {sid: m[max(m)] for sid, m in rec.modes.items() if m}
    ch = ctx.summary.get("channel") or {}
    by = link_by_type(ch.get("links") or [], ch.get("link_columns"))
    types = sorted(by)
    state = {k: sum(c[k] for c in by.get("p000-state", {}).values()) for k in ("tx_messages", "tx_payload_bytes")}
    hz1 = chase_steps * dt  # one state packet per chase/dock agent-second
    point = None
    if np.isfinite(rec.sc_q).all():
        point = pointing_error_deg(pos, rec.sc_q, rec.target_pos, t, tr.mean_motion_radps)
    dv = tr.delta_v_mps[-1]
    rate = rec.sc_w if rec.sc_w is not None and np.isfinite(rec.sc_w).all() else None
    est_axes = rec.est_axes if rec.est_axes is not None else np.full(pos.shape, np.nan)
    est_centre = rec.est_centre if rec.est_centre is not None else np.full(pos.shape, np.nan)
    ax_err, c_err = axes_error(est_axes, axes), centroid_error(est_centre, rec.target_pos)
    ax_fin, c_fin = last_finite(ax_err), last_finite(c_err)
    has_est = np.isfinite(ax_fin)

    met: dict[str, Any] = {
        "target": rec.target_id, "agents": ids, "window_s": [float(t[0]), float(t[-1])],
        "semi_axes_m": [float(x) for x in axes], "r_buffer_m": r_buffer,
        "chase_entry_s": {n: entry[n] for n in ids if n in entry},
        "in_chase_at_end": sum(1 for n in ids if last_mode.get(n, "search") != "search"),
        "final_mode": {n: last_mode.get(n) for n in ids},
        "surface_stride_steps": int(rows[1] - rows[0]) if len(rows) > 1 else 1,
        "min_surface_m": float(sd.min()),
        "min_surface_at": {"t_s": float(t[rows[s_arg[0]]]), "agent": ids[s_arg[1]]},
        "min_surface_per_agent_m": {n: float(sd[:, i].min()) for i, n in enumerate(ids)},
        "final_surface_m": {n: float(sd[-1, i]) for i, n in enumerate(ids)},
        "inside_target": bool(sd.min() < 0.0),
        "min_pair_m": float(pair.min()),
        "min_pair_at": {"t_s": float(t[p_arg[0]]), "pair": sorted([ids[p_arg[1]], ids[p_arg[2]]])},
        "dv_mps": {n: float(dv[i]) for i, n in enumerate(ids)},
        "total_dv_mps": float(dv.sum()),
        "link": {
            "per_type": {ty: {k: sum(c[k] for c in by[ty].values()) for k in next(iter(by[ty].values()))}
                         for ty in types},
            "per_agent": {n: {ty: by[ty][n] for ty in types if n in by[ty]} for n in ids},
            "totals": ch.get("totals") or {},
        },
        "state_msgs": state["tx_messages"], "state_bytes": state["tx_payload_bytes"],
        "chase_agent_steps": chase_steps,
        "every_step_ratio": state["tx_messages"] / max(chase_steps, 1),
        "hz1_ratio": state["tx_messages"] / max(hz1, 1e-9),
        "tx_recorded": len(rec.tx),
        # the agents' own estimates (telemetry Telemetry.items) against the truth, at their last estimate
        "agents_with_estimate": int(has_est.sum()),
        "axes_final_m": {n: [float(x) for x in last_finite(est_axes)[i]] for i, n in enumerate(ids) if has_est[i]},
        "axes_final_rel_err": {n: float(ax_fin[i]) for i, n in enumerate(ids) if has_est[i]},
        "axes_final_rel_err_max": float(np.max(ax_fin[has_est])) if has_est.any() else None,
        "axes_within_2pct": int(np.sum(ax_fin[has_est] <= 0.02)),
        "centroid_final_err_m": {n: float(c_fin[i]) for i, n in enumerate(ids) if has_est[i]},
        "centroid_final_err_max_m": float(np.max(c_fin[has_est])) if has_est.any() else None,
    }
    if rec.est_surface is not None and np.isfinite(rec.est_surface).any():
        met["min_surface_est_m"] = float(np.nanmin(rec.est_surface))  # what the agents believed
    if point is not None:
        met["pointing_final_deg"] = {n: float(point[-1, i]) for i, n in enumerate(ids)}
        met["pointing_final_max_deg"] = float(point[-1].max())
        settle = settle_time(t, point, 1.0)
        met["pointing_settled_1deg_s"] = {n: settle[i] for i, n in enumerate(ids)}
        met["pointing_settle_after_chase_s"] = {n: round(settle[i] - entry[n], 2) for i, n in enumerate(ids)
                                                if n in entry and settle[i] is not None}
    if rate is not None:
        met["max_body_rate_dps"] = float(np.degrees(np.linalg.norm(rate, axis=2).max()))

    return CaptureAnalysis(met=met, rec=rec, ids=ids, run=run, t=t, pos=pos, dt=dt, axes=axes, r_buffer=r_buffer,
                           rows=rows, sd=sd, s_arg=s_arg, pair=pair, entry=entry, types=types, point=point,
                           rate=rate, est_axes=est_axes, c_err=c_err, has_est=has_est, dv=dv)
