"""Report section of paper 004 (issue 15): six servicers converge on a defunct spacecraft.

Applies to runs flown with controller `p004-lbdnn`. Everything comes from the recording: the
servicers from ctx.truth (dashboards/truth_io.py, scenario frame = the defunct craft's LVLH for
deploy/scenarios/servicing-6.toml), the defunct craft from the raw Truth messages of ctx.mcap (a
body, not a spacecraft), the graph / C_i / b_i from the controller's params in ctx.config
(missions/p004_lbdnn/contract.py mission_from_params), link bytes from summary.json's channel
totals.

Metrics (`summary.json["metrics"]["p004-servicing"]`): the tracking errors ‖e_i‖ = ‖q0 − q_i‖
(frame-independent) per servicer and over the swarm — mean and max after STEADY_FROM_S, the time
from which all stay below TRACK_LEVEL_M —, the control effort ‖u_i‖ (the command applied over
[t_k, t_k+1), after the actuator limit; peak, mean after STEADY_FROM_S), Δv per servicer,
λ_min(H) of the configured graph and C_i, and the link's bytes.

Figures like the paper's: the servicers' paths relative to the defunct craft (Fig. 2: 3D over the
first PATH_WINDOW_S, with the three planar projections over the whole run), the tracking errors
(Fig. 4) and the control effort with the cumulative Δv (not a figure of the paper). Fig. 3, the
neighbourhood velocity-estimation error ‖ζ̃_i‖, needs the observers' state, which is not in the truth.

The scalar figures (`servicing_figures`, `first_time_below`, `tracking_errors`) are shared with
tests/missions/test_p004_stack.py, which computes them from its own reading of the MCAP.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.sections import (ErrorSeries, SectionContext, SectionResult, register_error_metric,
                                 register_section, uses_controller)
from swarmhil.dashboards.truth_io import TRUTH_SCHEMA, _truth_topic
from swarmhil.missions.p004_lbdnn.contract import mission_from_params

NAME = "p004-servicing"
CONTROLLER = "p004-lbdnn"
STEADY_FROM_S = 200.0     # §6: "after ≈ 200 s" the errors are a few metres
TRACK_LEVEL_M = 10.0      # time to below 10 m
PATH_WINDOW_S = 60.0      # Fig. 2 shows the first 60 s


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


# --- reading the recording --------------------------------------------------------------------------
def defunct_id(config: dict[str, Any]) -> str:
    """The defunct craft: the sensing kind's defunct_id, else the configuration's first body."""
    sid = ((config.get("sensing") or {}).get("params") or {}).get("defunct_id")
    if sid:
        return str(sid)
    bodies = config.get("body") or []
    if not bodies:
        raise ValueError("the recording's configuration has no body (defunct craft)")
    return str(bodies[0]["id"])


def read_body(mcap_path: Path, body_id: str, run: str | None = None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{step: (position, velocity)} of one body (any kind) from the recording's Truth messages
    (scenario frame), with the standard reader (mcap + mcap-protobuf-support)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    rows: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topic, _run = _truth_topic(reader, run)
        for schema, _ch, _msg, truth in reader.iter_decoded_messages(topics=[topic]):
            if schema is None or schema.name != TRUTH_SCHEMA:
                continue
            step = int(truth.header.step)
            if step in rows:
                continue
            for b in truth.bodies:
                if b.id == body_id:
                    rows[step] = (np.array([b.position_m.x, b.position_m.y, b.position_m.z]),
                                  np.array([b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z]))
                    break
    return rows


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _servicers(config: dict[str, Any], ids: list[str]) -> list[str]:
    """The spacecraft flown by p004-lbdnn (all of them when it is the swarm's controller)."""
    swarm = str((config.get("controller") or {}).get("name")) == CONTROLLER
    own = {str(s["id"]): s.get("controller") for s in config.get("spacecraft") or []}
    return [i for i in ids if (own.get(i) == CONTROLLER) or (swarm and not own.get(i))]


def _mission(config: dict[str, Any]):
    return mission_from_params(dict((config.get("controller") or {}).get("params") or {}))


def compute(ctx: SectionContext) -> tuple[dict[str, Any], dict[str, Any]]:
    """(metrics for summary.json, arrays for the figures)."""
    truth, cfg = ctx.truth, ctx.config
    dfid = defunct_id(cfg)
    body = read_body(ctx.mcap, dfid, truth.run)
    missing = [int(k) for k in truth.step if int(k) not in body]
    if missing:
        raise ValueError(f"{dfid!r} is missing from the Truth messages of steps {missing[:5]}...")
    q0 = np.array([body[int(k)][0] for k in truth.step])
    sv = _servicers(cfg, truth.ids)
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
    mission = _mission(cfg)
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


@register_error_metric(NAME, applies=lambda cfg: uses_controller(cfg, CONTROLLER))
def largest_tracking_error(ctx: SectionContext) -> ErrorSeries:
    """max_i ‖q0 − q_i‖ over the servicers per step (§6's tracking error, eq. (5)): the faults
    section's per-mission excursion."""
    truth, cfg = ctx.truth, ctx.config
    body = read_body(ctx.mcap, defunct_id(cfg), truth.run)
    keep = np.array([int(k) in body for k in truth.step])
    q0 = np.array([body[int(k)][0] for k in truth.step if int(k) in body]).reshape(-1, 3)
    cols = [truth.ids.index(s) for s in _servicers(cfg, truth.ids)]
    e = tracking_errors(q0, truth.position_m[keep][:, cols])
    return ErrorSeries("largest servicer tracking error", "m", truth.t_s[keep], e.max(axis=1))


# --- figures ----------------------------------------------------------------------------------------
def _window(t: np.ndarray) -> tuple[float, str]:
    """The zoom window of a run: from STEADY_FROM_S if the run gets there, else its second half."""
    if t[-1] > STEADY_FROM_S:
        return STEADY_FROM_S, f"t ≥ {STEADY_FROM_S:g} s"
    t0 = float(t[0] + 0.5 * (t[-1] - t[0]))
    return t0, f"t ≥ {t0:g} s (second half: the run ends before {STEADY_FROM_S:g} s)"


def fig_tracking(a: dict[str, Any], met: dict[str, Any], path: Path) -> str:

    plt = _plt()
    t, e, ids = a["t"], a["e"], a["ids"]
    col = _colors(len(ids))
    t0, wlabel = _window(t)
    w = t >= t0
    fig, ax = plt.subplots(2, 1, figsize=(8, 6))
    for j, s in enumerate(ids):
        ax[0].semilogy(t, np.maximum(e[:, j], 1e-3), color=col[j], lw=1.0, label=s)
        ax[1].plot(t[w], e[w, j], color=col[j], lw=1.0, label=s)
    for x in ax:
        x.axhline(TRACK_LEVEL_M, color="r", ls="--", lw=0.8)
        x.set_ylabel("‖e_i‖ = ‖q0 − q_i‖ [m]")
    ax[0].axvspan(t0, t[-1], color="0.85", alpha=0.5, lw=0)
    tb = met["t_all_below_10m_s"]
    if tb is not None:
        ax[0].axvline(tb, color="k", ls=":", lw=0.8)
    when = f"all below {TRACK_LEVEL_M:g} m from t = {tb:.1f} s" if tb is not None else \
        f"not all below {TRACK_LEVEL_M:g} m at the end ({t[-1]:.0f} s)"
    ax[0].set_title(f"Tracking errors of {len(ids)} servicers (paper Fig. 4): {when}")
    ax[0].legend(ncol=min(6, len(ids)), loc="upper right")
    ax[1].set_title(f"{wlabel}: mean {float(e[w].mean()):.2f} m, max {float(e[w].max()):.2f} m")
    ax[1].set_xlabel("t [s]")
    return _save(fig, path)


def fig_effort(a: dict[str, Any], met: dict[str, Any], path: Path) -> str:

    plt = _plt()
    t, u, dv, ids = a["t"], a["u"], a["dv"], a["ids"]
    col = _colors(len(ids))
    t0, wlabel = _window(t)
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for j, s in enumerate(ids):
        ax[0].step(t[:-1], np.maximum(u[:, j], 1e-9), where="post", color=col[j], lw=0.9, label=s)
        ax[1].plot(t, dv[:, j], color=col[j], lw=1.0, label=f"{s}: {dv[-1, j]:.1f} m/s")
    ax[0].set_yscale("log")
    ax[0].axvspan(t0, t[-1], color="0.85", alpha=0.5, lw=0)
    ax[0].set_ylabel("‖u_i‖ [m/s²]")
    um = met["u_mean_after_200s_mps2"]
    wm = float(u[t[:-1] >= t0].mean()) if (t[:-1] >= t0).any() else float("nan")
    ax[0].set_title(f"Control effort: peak {met['u_peak_mps2']:.3g} m/s²,\nmean "
                    + (f"{um:.3g} m/s² after {STEADY_FROM_S:g} s" if um is not None else f"{wm:.3g} m/s² over {wlabel}"))
    ax[0].legend(ncol=min(6, len(ids)), loc="upper right")
    ax[1].set_ylabel("cumulative Δv [m/s]")
    ax[1].set_xlabel("t [s]")
    ax[1].set_title(f"Δv per servicer, total {met['delta_v_total_mps']:.1f} m/s")
    ax[1].legend(ncol=3, loc="lower right")
    return _save(fig, path)


def fig_paths(a: dict[str, Any], met: dict[str, Any], path: Path) -> str:

    plt = _plt()
    t, rel, ids = a["t"], a["rel"], a["ids"]
    col = _colors(len(ids))
    t_win = min(float(t[0]) + PATH_WINDOW_S, float(t[-1]))
    w = t <= t_win
    fig = plt.figure(figsize=(10, 8))
    ax3 = fig.add_subplot(2, 2, 1, projection="3d")
    planes = [((0, 1), "radial x [m]", "in-track y [m]"), ((1, 2), "in-track y [m]", "cross-track z [m]"),
              ((0, 2), "radial x [m]", "cross-track z [m]")]
    axs = [fig.add_subplot(2, 2, k + 2) for k in range(3)]
    for j, s in enumerate(ids):
        r = rel[:, j]
        ax3.plot(r[w, 0], r[w, 1], r[w, 2], color=col[j], lw=1.0, label=s)
        ax3.scatter(*r[0], color=col[j], marker="o", s=12)
        for ax, ((p, q), _xl, _yl) in zip(axs, planes):
            ax.plot(r[:, p], r[:, q], color=col[j], lw=1.0)
            ax.plot(r[0, p], r[0, q], "o", color=col[j], ms=3)
            ax.plot(r[-1, p], r[-1, q], "x", color=col[j], ms=4)
    ax3.scatter([0], [0], [0], color="k", marker="*", s=60, label=met["defunct_id"])
    ax3.set_xlabel("x [m]")
    ax3.set_ylabel("y [m]")
    ax3.set_zlabel("z [m]")
    ax3.set_title(f"3D, t ≤ {t_win:g} s (paper Fig. 2: the first {PATH_WINDOW_S:g} s)")
    ax3.legend(loc="upper left", fontsize=6)
    for ax, (_pq, xl, yl) in zip(axs, planes):
        ax.plot([0], [0], "k*", ms=8)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_aspect("equal", adjustable="datalim")
    axs[0].set_title(f"whole run, {t[0]:g}-{t[-1]:g} s (o start, x end)")
    fig.suptitle(f"Servicers relative to {met['defunct_id']}: from ≥ {met['e_start_min_m']:.0f} m "
                 f"to ≤ {met['e_end_max_m']:.1f} m in {t[-1] - t[0]:.0f} s")
    return _save(fig, path)


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
