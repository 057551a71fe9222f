"""Report section of paper 000 (issue 12): a swarm searches, fits and encloses a tumbling ellipsoidal
target, broadcasting its state on an event trigger (docs/paper000.md).

Applies to runs whose spacecraft flew "p000-capture". Everything comes from the recording:
spacecraft positions, accelerations and dV from ctx.truth; the target's pose and attitude and the
spacecraft attitudes from the raw Truth messages (standard mcap reader); each agent's mode from its
`sc/<id>/tm` telemetry; the packets sent from the `isl/tx/<id>` topics; the link's per-type counters
from summary.json["channel"]; from ctx.config the target's semi-axes and the controller's params
(controller.params merged with each spacecraft's params, as deploy/scenario.py).

Signed distances use the room's closest-point routine (missions/p000_capture/contract.py) on
the TRUE target. The pure functions here (`surface_distance`, `chase_entry`, `link_by_type`,
`pair_distance`) are also what tests/missions/test_p000_stack.py computes its figures with.
"""
from __future__ import annotations

import html
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.bus.codec import measurements_to_dict
from swarmhil.bus.keys import split_topic
from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.rerun_bodies import register_landmark_kind
from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section, uses_controller
from swarmhil.dashboards.truth_io import TRUTH_SCHEMA, _truth_topic
from swarmhil.missions.p000_capture.contract import (
    CONTROLLER,
    LANDMARK_IDS,
    LANDMARKS_BODY_M,
    SENSING_KIND,
    CaptureParams,
    Ellipsoid,
    dcm,
    signed_distance,
)

register_landmark_kind(SENSING_KIND, LANDMARKS_BODY_M, LANDMARK_IDS)  # the viewer's sensor cone and returns

MAX_SURFACE_ROWS = 2000  # signed distance on at most this many recorded steps (always the last)


# --- reading the recording ----------------------------------------------------------------------------
@dataclass
class CaptureRecording:
    """What the section reads from the MCAP besides ctx.truth (rows = Truth steps, sorted)."""

    steps: np.ndarray            # (K,)
    target_id: str
    target_pos: np.ndarray       # (K, 3) CW frame
    target_q: np.ndarray         # (K, 4) scalar-first, body -> CW frame (the target's attitude in truth)
    sc_q: np.ndarray             # (K, N, 4) body -> inertial frame aligned with CW at t = 0 (NaN if not flown)
    modes: dict[str, dict[int, str]]      # id -> step -> telemetry mode
    tx: list[tuple[str, str, int, int]]   # (src, type, payload bytes, step) of every isl/tx packet
    sc_w: np.ndarray | None = None        # (K, N, 3) body rates [rad/s] (NaN if not flown)
    est_axes: np.ndarray | None = None    # (K, N, 3) the agent's sorted semi-axes estimate (telemetry; NaN: none)
    est_centre: np.ndarray | None = None  # (K, N, 3) its centroid estimate at that step (CW frame)
    est_surface: np.ndarray | None = None  # (K, N) its signed distance to its ESTIMATED surface


def read_capture(mcap: Path, ids: list[str], run: str | None = None) -> CaptureRecording:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    tgt: dict[int, tuple] = {}
    att: dict[int, np.ndarray] = {}
    modes: dict[str, dict[int, str]] = {}
    tx: list[tuple[str, str, int, int]] = []
    rates: dict[int, np.ndarray] = {}
    est: dict[tuple[int, int], dict[str, np.ndarray]] = {}  # (step, column) -> telemetry items
    tid = ""
    col = {s: j for j, s in enumerate(ids)}
    with open(mcap, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        truth_topic, _run = _truth_topic(reader, run)
        summ = reader.get_summary()
        topics = [truth_topic] + sorted({
            ch.topic for ch in (summ.channels.values() if summ is not None else [])
            if (split_topic(ch.topic)[1].startswith("sc/") and split_topic(ch.topic)[1].endswith("/tm"))
            or split_topic(ch.topic)[1].startswith("isl/tx/")})
        for schema, ch, _msg, m in reader.iter_decoded_messages(topics=topics):  # not the big sensing ones
            rel = split_topic(ch.topic)[1]
            if ch.topic == truth_topic:
                k = int(m.header.step)
                if schema is None or schema.name != TRUTH_SCHEMA or k in tgt:
                    continue
                q = np.full((len(ids), 4), np.nan)
                w = np.full((len(ids), 3), np.nan)
                for b in m.bodies:
                    if b.kind == "target" and k not in tgt:
                        tid = b.id
                        tgt[k] = ((b.position_m.x, b.position_m.y, b.position_m.z),
                                  (b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z))
                    elif b.kind == "spacecraft" and b.id in col and b.HasField("attitude"):
                        q[col[b.id]] = (b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z)
                        if b.HasField("angular_velocity_radps"):
                            av = b.angular_velocity_radps
                            w[col[b.id]] = (av.x, av.y, av.z)
                att[k], rates[k] = q, w
            elif rel.startswith("sc/") and rel.endswith("/tm"):
                sid = m.header.source or rel.split("/")[1]
                modes.setdefault(sid, {})[int(m.header.step)] = m.mode
                if len(m.items) and sid in col:
                    est[(int(m.header.step), col[sid])] = measurements_to_dict(m)
            elif rel.startswith("isl/tx/"):
                tx.append((m.src, m.type, len(m.payload), int(m.header.step)))
    if not tgt:
        raise ValueError(f"{mcap}: no body of kind 'target' in the truth")
    steps = np.array(sorted(tgt))
    row = {int(k): r for r, k in enumerate(steps)}
    e_axes = np.full((len(steps), len(ids), 3), np.nan)
    e_centre, e_surf = e_axes.copy(), np.full((len(steps), len(ids)), np.nan)
    for (k, j), items in est.items():
        if k in row:
            e_axes[row[k], j] = items.get("p000_axes_est_m", np.nan)
            e_centre[row[k], j] = items.get("p000_centre_est_m", np.nan)
            e_surf[row[k], j] = np.ravel(items.get("p000_surface_est_m", [np.nan]))[0]
    return CaptureRecording(
        steps=steps, target_id=tid, target_pos=np.array([tgt[k][0] for k in steps], dtype=float),
        target_q=np.array([tgt[k][1] for k in steps], dtype=float),
        sc_q=np.array([att[k] for k in steps], dtype=float), modes=modes, tx=tx,
        sc_w=np.array([rates[k] for k in steps], dtype=float), est_axes=e_axes, est_centre=e_centre,
        est_surface=e_surf)


# --- pure computations (shared with tests/missions/test_p000_stack.py) ----------------------------------
def target_axes(cfg: dict[str, Any] | None) -> np.ndarray:
    """The semi-axes of the configuration's body of kind "target" (an ellipsoid)."""
    for b in (cfg or {}).get("body") or []:
        if b.get("kind") == "target" and (b.get("shape") or {}).get("kind") == "ellipsoid":
            return np.asarray(b["shape"]["semi_axes_m"], dtype=float)
    raise ValueError("the configuration has no ellipsoidal body of kind 'target'")


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


def capture_params(cfg: dict[str, Any] | None, sid: str):

    cfg = cfg or {}
    scs = {str(s["id"]): s for s in cfg.get("spacecraft") or []}
    p = {**((cfg.get("controller") or {}).get("params") or {}), **((scs.get(sid) or {}).get("params") or {})}
    return CaptureParams.from_dict(p)


# --- figures ----------------------------------------------------------------------------------------
def _window(t: np.ndarray) -> str:
    return f"t = {t[0]:.1f}-{t[-1]:.1f} s"


def fig_paths(pos: np.ndarray, rec: CaptureRecording, axes: np.ndarray, r_buffer: float, ids: list[str],
              run: str, t: np.ndarray, path: Path) -> str:
    """Trajectories relative to the target's centre around the target ellipsoid at the last step."""
    plt = _plt()
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    u, v = np.mgrid[0:2 * np.pi:24j, 0:np.pi:13j]
    unit = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    rot = dcm(rec.target_q[-1])
    surf = (unit * axes) @ rot.T
    ax.plot_wireframe(surf[..., 0], surf[..., 1], surf[..., 2], color="0.45", lw=0.4)
    shell = (unit * (axes + r_buffer)) @ rot.T  # the buffer shell, approximately (axes + R_buffer)
    ax.plot_wireframe(shell[..., 0], shell[..., 1], shell[..., 2], color="0.8", lw=0.2)
    rel = pos - rec.target_pos[:, None, :]
    col = _colors(len(ids))
    for i, n in enumerate(ids):
        ax.plot(rel[:, i, 0], rel[:, i, 1], rel[:, i, 2], color=col[i], lw=0.9, label=n)
        ax.scatter(*rel[0, i], color=col[i], marker="o", s=10)
        ax.scatter(*rel[-1, i], color=col[i], marker="s", s=14)
    lim = float(np.nanmax(np.abs(rel))) if rel.size else 10.0
    for setl in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        setl(-lim, lim)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.set_title(f"{run}:\npaths relative to the target centre ({_window(t)}); target at the end")
    ax.legend(loc="upper left", fontsize=6, ncol=2)
    return _save(fig, path)


def fig_surface(ts: np.ndarray, sd: np.ndarray, entry: dict[str, float], r_buffer: float, ids: list[str],
                run: str, path: Path) -> str:

    plt = _plt()
    col = _colors(len(ids))
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, n in enumerate(ids):
        ax.plot(ts, sd[:, i], color=col[i], lw=0.9, label=n)
        if n in entry:
            ax.axvline(entry[n], color=col[i], ls=":", lw=0.6)
    ax.axhline(0.0, color="r", lw=1.0, label="true surface")
    ax.axhline(r_buffer, color="k", ls="--", lw=0.8, label=f"R_buffer {r_buffer:g} m")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("signed distance to the true surface [m]")
    ax.set_title(f"{run}: distance to the target surface (dotted: chase entries); min {np.min(sd):.3g} m")
    ax.legend(loc="upper right", fontsize=6, ncol=2)
    return _save(fig, path)


def fig_pairs(t: np.ndarray, pair: np.ndarray, ids: list[str], run: str, path: Path) -> str:

    plt = _plt()
    col = _colors(len(ids))
    nearest = pair.min(axis=2)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, n in enumerate(ids):
        ax.plot(t, nearest[:, i], color=col[i], lw=0.7, alpha=0.7, label=n)
    ax.plot(t, nearest.min(axis=1), color="k", lw=1.4, label="swarm minimum")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("distance to the nearest agent [m]")
    ax.set_title(f"{run}: pair distances; min {nearest.min():.3g} m")
    ax.legend(loc="upper right", fontsize=6, ncol=2)
    return _save(fig, path)


def fig_messages(tx: list[tuple[str, str, int, int]], dt_s: float, t_end: float, ids: list[str],
                 types: list[str], run: str, path: Path) -> str:
    """Cumulative packets sent per agent over time, one panel per message type (isl/tx topics)."""

    plt = _plt()
    col = _colors(len(ids))
    types = types or ["(none)"]
    fig, axs = plt.subplots(len(types), 1, figsize=(8, 2.8 * len(types) + 0.6), sharex=True, squeeze=False)
    for a, typ in zip(axs[:, 0], types):
        for i, n in enumerate(ids):
            ks = np.sort([k for s, ty, _b, k in tx if s == n and ty == typ]) * dt_s
            if len(ks):
                a.step(np.r_[0.0, ks, t_end], np.r_[0, np.arange(1, len(ks) + 1), len(ks)], where="post",
                       color=col[i], lw=0.9, label=n)
        a.set_ylabel(f"{typ}\ncumulative sent")
        a.legend(loc="upper left", fontsize=6, ncol=2)
    axs[-1, 0].set_xlabel("t [s]")
    axs[0, 0].set_title(f"{run}: messages sent per agent (isl/tx)")
    return _save(fig, path)


def fig_pointing(t: np.ndarray, err: np.ndarray, rate: np.ndarray | None, ids: list[str], run: str,
                 path: Path) -> str:
    """Attitude errors (Fig. 5): pointing error to the true centroid and, if flown, the body rate."""

    plt = _plt()
    col = _colors(len(ids))
    fig, axs = plt.subplots(2 if rate is not None else 1, 1, figsize=(8, 6.5 if rate is not None else 4),
                            sharex=True, squeeze=False)
    ax = axs[0, 0]
    for i, n in enumerate(ids):
        ax.plot(t, err[:, i], color=col[i], lw=0.8, label=n)
    ax.set_yscale("log")
    ax.set_ylabel("boresight to true centroid [deg]")
    ax.set_title(f"{run}: attitude errors")
    ax.legend(loc="upper right", fontsize=6, ncol=2)
    if rate is not None:
        for i, n in enumerate(ids):
            axs[1, 0].plot(t, np.degrees(np.linalg.norm(rate[:, i], axis=1)), color=col[i], lw=0.8)
        axs[1, 0].set_yscale("log")
        axs[1, 0].set_ylabel("body rate |omega| [deg/s]")
    axs[-1, 0].set_xlabel("t [s]")
    return _save(fig, path)


def fig_axes(t: np.ndarray, est_axes: np.ndarray, axes: np.ndarray, ids: list[str], run: str, path: Path) -> str:
    """Figs. 7 and 12: each agent's sorted semi-axes estimate (telemetry) against the truth."""

    plt = _plt()
    col = _colors(len(ids))
    a = np.sort(axes)
    fig, axs = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    for k, (ax, name) in enumerate(zip(axs[::-1], ("a (largest)", "b", "c (smallest)")[::-1])):
        for i, n in enumerate(ids):
            ax.plot(t, est_axes[:, i, k], color=col[i], lw=0.8, label=n)
        ax.axhline(a[k], color="k", ls="--", lw=1.2, label=f"truth {a[k]:g} m")
        ax.set_ylim(0.8 * a[k], 1.2 * a[k])
        ax.set_ylabel(f"{name} [m]")
    axs[0].set_title(f"{run}: estimated semi-axes (sorted) vs truth; y range truth ±20 %")
    axs[0].legend(loc="upper right", fontsize=6, ncol=3)
    axs[-1].set_xlabel("t [s]")
    return _save(fig, path)


def fig_centroid(t: np.ndarray, err: np.ndarray, ids: list[str], run: str, path: Path) -> str:

    plt = _plt()
    col = _colors(len(ids))
    fig, ax = plt.subplots(figsize=(8, 4))
    for i, n in enumerate(ids):
        ax.plot(t, err[:, i], color=col[i], lw=0.8, label=n)
    ax.set_yscale("log")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("|estimated - true centre| [m]")
    ax.set_title(f"{run}: centroid error of each agent's estimate")
    ax.legend(loc="upper right", fontsize=6, ncol=2)
    return _save(fig, path)


def fig_triggers(tx: list[tuple[str, str, int, int]], dt_s: float, t_end: float, ids: list[str], run: str,
                 path: Path, typ: str = "p000-state") -> str:
    """Trigger instants: one row per agent, a tick per state broadcast (isl/tx)."""

    plt = _plt()
    col = _colors(len(ids))
    fig, ax = plt.subplots(figsize=(8, 0.25 * len(ids) + 1.5))
    for i, n in enumerate(ids):
        ks = np.array([k for s, ty, _b, k in tx if s == n and ty == typ], dtype=float) * dt_s
        ax.vlines(ks, i - 0.4, i + 0.4, color=col[i], lw=0.5)
    ax.set_yticks(range(len(ids)), ids, fontsize=7)
    ax.set_xlim(0.0, t_end)
    ax.set_xlabel("t [s]")
    ax.set_title(f"{run}: trigger instants ({typ} broadcasts)")
    return _save(fig, path)


# --- the section --------------------------------------------------------------------------------------
def _table(rows: list[tuple[str, str]]) -> str:
    return "<table>" + "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows) + "</table>"


@register_section("p000-capture", applies=lambda cfg: uses_controller(cfg, CONTROLLER))
def capture(ctx: SectionContext) -> SectionResult:
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
        ("window", _window(t)),
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
