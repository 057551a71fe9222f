"""Report section of paper 003 (issue 14): a leader tracks an escaping target inside an arctan funnel,
six servicers hold slots around the target's structure (docs/paper003.md).

Applies to runs whose spacecraft flew "p003-leader". Everything comes from the recording: the
spacecraft from ctx.truth, the target (Truth bodies of kind "target") from ctx.mcap with the standard
mcap reader, and from ctx.config the target's sphere structure, the masses and force limits and the
controllers' params (controller.params merged with each spacecraft's params, as deploy/scenario.py).

`surround_metrics` is also what tests/missions/test_p003_stack.py computes its figures with.
"""
from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.sections import (ErrorSeries, SectionContext, SectionResult, register_error_metric,
                                 register_section, uses_controller)
from swarmhil.dashboards.truth_io import TRUTH_SCHEMA, _truth_topic
from swarmhil.missions.p003_surround.contract import (
    LEADER_CONTROLLER,
    SERVICER_CONTROLLER,
    SLOT_OFFSETS_M,
    FunnelParams,
    GameParams,
    from_dict,
    funnel_half_width,
    performance,
    servicer_index,
    slots_in_leader_frame,
    sphere_arrays,
    transformed_error,
)


@dataclass(frozen=True)
class SurroundSetup:
    """Who is who in a run and the numbers the metrics need (from the configuration, or §5 defaults)."""

    leader: int                 # column of the leader in the truth arrays
    servicers: list[int]        # columns of the servicers
    slot_index: list[int]       # each servicer's slot (Table 1 row)
    funnel: Any                 # FunnelParams of the leader
    game: Any                   # GameParams of the servicers (the first one's)
    q_des_m: np.ndarray         # q_TL,d
    slots_m: np.ndarray         # (S, 3) desired servicer positions in the leader's LVLH, servicer order
    centres_m: np.ndarray       # (G, 3) sphere centres d_Cg in the target's frame
    radii_m: np.ndarray         # (G,)
    leader_mass_kg: float
    servicer_mass_kg: np.ndarray  # (S,)
    leader_limit_n: float       # the plant's force limit (max_force_n), else the controller's
    servicer_limit_n: np.ndarray  # (S,)


def _sc_controller(cfg: dict[str, Any], s: dict[str, Any]) -> str:
    return str(s.get("controller") or (cfg.get("controller") or {}).get("name"))


def _sc_params(cfg: dict[str, Any], s: dict[str, Any]) -> dict[str, Any]:
    return {**((cfg.get("controller") or {}).get("params") or {}), **(s.get("params") or {})}


def setup_from_config(cfg: dict[str, Any] | None, ids: list[str]) -> SurroundSetup:
    """The setup of a run from its resolved configuration; without one (old recording), the §5
    defaults with "lsat" the leader, every other spacecraft a servicer and the Table 2 spheres."""

    cfg = cfg or {}
    scs = {str(s["id"]): s for s in cfg.get("spacecraft") or []}
    if scs:
        leader_ids = [i for i in ids if _sc_controller(cfg, scs[i]) == LEADER_CONTROLLER]
        sat_ids = [i for i in ids if _sc_controller(cfg, scs[i]) == SERVICER_CONTROLLER]
    else:
        leader_ids, sat_ids = ["lsat"], [i for i in ids if i != "lsat"]
    if len(leader_ids) != 1:
        raise ValueError(f"expected one {LEADER_CONTROLLER} spacecraft, found {leader_ids}")
    lid = leader_ids[0]
    lp = _sc_params(cfg, scs[lid]) if scs else {}
    sp = [_sc_params(cfg, scs[i]) if scs else {} for i in sat_ids]
    funnel = from_dict(FunnelParams, lp.get("funnel"))
    game = from_dict(GameParams, sp[0].get("game") if sp else None)
    sat_funnels = [from_dict(FunnelParams, p.get("funnel")) for p in sp]
    slot_index = [servicer_index(i, p) for i, p in zip(sat_ids, sp)]
    slots = np.array([slots_in_leader_frame(np.asarray(f.q_des_m), SLOT_OFFSETS_M)[k]
                      for f, k in zip(sat_funnels, slot_index)]).reshape(-1, 3)
    target = [b for b in cfg.get("body") or [] if b.get("kind") == "target"]
    shape = (target[0].get("shape") or {}) if target else {}
    if shape.get("kind") == "spheres":
        centres = np.asarray(shape["centers_m"], dtype=float).reshape(-1, 3)
        radii = np.asarray(shape["radii_m"], dtype=float)
    else:
        centres, radii = sphere_arrays()

    def mass(i: str, default: float) -> float:
        return float(scs[i].get("mass_kg") or default) if scs else default

    def limit(i: str, default: float) -> float:
        s = scs.get(i) or {}
        if s.get("max_force_n") is not None:
            return float(s["max_force_n"])
        if s.get("max_accel_mps2") is not None:
            return float(s["max_accel_mps2"]) * mass(i, default)
        return default

    return SurroundSetup(
        leader=ids.index(lid), servicers=[ids.index(i) for i in sat_ids], slot_index=slot_index,
        funnel=funnel, game=game, q_des_m=np.asarray(funnel.q_des_m, dtype=float), slots_m=slots,
        centres_m=centres, radii_m=radii, leader_mass_kg=mass(lid, funnel.mass_kg),
        servicer_mass_kg=np.array([mass(i, game.mass_kg) for i in sat_ids]),
        leader_limit_n=limit(lid, funnel.max_thrust_n),
        servicer_limit_n=np.array([limit(i, game.max_thrust_n) for i in sat_ids]))


def surround_metrics(t: np.ndarray, pos: np.ndarray, vel: np.ndarray, accel_steps: np.ndarray,
                     target_pos: np.ndarray, su: SurroundSetup) -> dict[str, Any]:
    """Series and figures of paper 003 from truth (leader's LVLH, K recorded steps, N spacecraft).

    accel_steps (K-1, N, 3): the command applied over each step [t_k, t_k+1). Thrust = |a| m with the
    configured masses. The funnel bound is infinite at t = 0, so ratios start at the second row."""

    fp = su.funnel
    lead, sats = su.leader, su.servicers
    q_tl = target_pos - pos[:, lead]
    tt = q_tl - su.q_des_m
    fw = np.array([funnel_half_width(x, fp.mu1, fp.a1_per_s) for x in t])
    k1 = np.array([performance(x, fp.mu1, fp.a1_per_s) for x in t])
    q_s = pos[:, sats] - pos[:, lead:lead + 1]
    v_s = vel[:, sats] - vel[:, lead:lead + 1]
    ct_pos = np.linalg.norm(q_s - su.slots_m[None], axis=2)
    ct_vel = np.linalg.norm(v_s, axis=2)
    centres = target_pos[:, None, :] + su.centres_m[None]           # (K, G, 3)
    surf = np.linalg.norm(pos[:, sats, None, :] - centres[:, None], axis=3) - su.radii_m[None, None]  # (K, S, G)
    clear = surf.min(axis=2)
    pair = np.linalg.norm(q_s[:, :, None] - q_s[:, None], axis=3) + np.diag(np.full(len(sats), np.inf))[None]
    lead_n = np.linalg.norm(accel_steps[:, lead], axis=1) * su.leader_mass_kg
    sat_n = np.linalg.norm(accel_steps[:, sats], axis=2) * su.servicer_mass_kg[None]
    ratio = np.abs(tt[1:]).max(axis=1) / fw[1:]
    return {
        "t": t, "tt_err_m": tt, "funnel_m": fw, "tt_transformed": transformed_error(tt, 1.0) / k1[:, None],
        "ct_pos_m": ct_pos, "ct_vel_mps": ct_vel, "clearance_m": clear, "sphere_surface_m": surf,
        "pair_m": pair, "min_pair_m": pair.min(axis=(1, 2)), "leader_n": lead_n, "sat_n": sat_n,
        "tt_ratio": ratio,
        "tt_err_end_m": float(np.abs(tt[-1]).max()), "funnel_end_m": float(fw[-1]),
        "worst_tt_ratio": float(ratio.max()),
        "ct_pos_end_m": float(ct_pos[-1].max()), "ct_vel_end_mps": float(ct_vel[-1].max()),
        "min_clearance_m": float(clear.min()), "min_pair_end_m": float(pair.min()),
        "leader_peak_n": float(lead_n.max()), "sat_peak_n": float(sat_n.max()),
        "sat_saturated_frac": float((sat_n > su.servicer_limit_n[None] * (1 - 1e-9)).mean()),
    }


def read_target(mcap: Path, run: str | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """(steps, position (K, 3), velocity (K, 3), id) of the body of kind "target" in the recording's
    Truth messages (standard mcap reader, the truth topic as dashboards/truth_io.py finds it)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    rows: dict[int, tuple] = {}
    tid = ""
    with open(mcap, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topic, _run = _truth_topic(reader, run)
        for schema, _ch, _msg, m in reader.iter_decoded_messages(topics=[topic]):
            if schema is None or schema.name != TRUTH_SCHEMA or int(m.header.step) in rows:
                continue
            for b in m.bodies:
                if b.kind == "target":
                    tid = b.id
                    rows[int(m.header.step)] = ((b.position_m.x, b.position_m.y, b.position_m.z),
                                                (b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z))
                    break
    if not rows:
        raise ValueError(f"{mcap}: no body of kind 'target' in the truth")
    steps = np.array(sorted(rows))
    return (steps, np.array([rows[k][0] for k in steps], dtype=float),
            np.array([rows[k][1] for k in steps], dtype=float), tid)


# --- figures ----------------------------------------------------------------------------------------
def _window(t: np.ndarray) -> str:
    return f"t = {t[0]:.1f}-{t[-1]:.1f} s"


def fig_tt(m: dict, run: str, path: Path) -> str:
    """Figs. 6-8: TT error per axis inside the funnel ±tan(k1 π/2), and the transformed errors."""

    plt = _plt()
    t, tt, fw = m["t"], m["tt_err_m"], m["funnel_m"]
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for a, lab in enumerate("xyz"):
        ax[0].plot(t, tt[:, a], lw=1.0, label=f"q~_TL,{lab}")
        ax[1].plot(t[1:], m["tt_transformed"][1:, a], lw=1.0, label=f"e_{lab} = arctan(q~)/k1")
    ax[0].fill_between(t[1:], -fw[1:], fw[1:], color="0.85", label="funnel ±tan(k1 π/2)")
    ax[0].plot(t[1:], fw[1:], "k--", lw=0.8)
    ax[0].plot(t[1:], -fw[1:], "k--", lw=0.8)
    ax[0].set_yscale("symlog", linthresh=10.0)
    ax[0].set_ylabel("TT error [m]")
    ax[0].set_title(f"{run}: leader tracking error inside the funnel ({_window(t)}); worst |err|/bound "
                    f"{m['worst_tt_ratio']:.3g}")
    ax[0].legend(loc="upper right")
    ax[1].axhline(np.pi / 2, color="k", ls="--", lw=0.8)
    ax[1].axhline(-np.pi / 2, color="k", ls="--", lw=0.8)
    ax[1].set_ylabel("transformed error [-]")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="upper right")
    return _save(fig, path)


def fig_ct(m: dict, names: list[str], run: str, path: Path) -> str:
    """Figs. 13-14: servicer slot position and velocity errors."""

    plt = _plt()
    t, col = m["t"], _colors(len(names))
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for j, n in enumerate(names):
        ax[0].plot(t, m["ct_pos_m"][:, j], color=col[j], lw=1.0, label=n)
        ax[1].plot(t, m["ct_vel_mps"][:, j], color=col[j], lw=1.0, label=n)
    ax[0].axhline(5.0, color="r", ls=":", lw=0.8, label="5 m (§5 claim)")
    ax[1].axhline(0.5, color="r", ls=":", lw=0.8, label="0.5 m/s (§5 claim)")
    ax[0].set_yscale("log")
    ax[1].set_yscale("log")
    ax[0].set_ylabel("|q_Li - q_Li,d| [m]")
    ax[1].set_ylabel("|v_Li| [m/s]")
    ax[1].set_xlabel("t [s]")
    ax[0].set_title(f"{run}: servicer slot errors relative to the leader ({_window(t)})")
    ax[0].legend(loc="upper right", ncol=2)
    return _save(fig, path)


def fig_paths(pos: np.ndarray, target_pos: np.ndarray, su: SurroundSetup, names: list[str], run: str,
              t: np.ndarray, path: Path) -> str:
    """Figs. 10-12: 3D paths relative to the target around its structure spheres, slots marked."""

    plt = _plt()
    fig = plt.figure(figsize=(8, 7))
    ax = fig.add_subplot(projection="3d")
    u, v = np.mgrid[0:2 * np.pi:16j, 0:np.pi:9j]
    sx, sy, sz = np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)
    for c, r in zip(su.centres_m, su.radii_m):
        ax.plot_wireframe(c[0] + r * sx, c[1] + r * sy, c[2] + r * sz, color="0.6", lw=0.3)
    rel = pos - target_pos[:, None, :]
    col = _colors(len(names))
    for j, (i, n) in enumerate(zip(su.servicers, names)):
        ax.plot(rel[:, i, 0], rel[:, i, 1], rel[:, i, 2], color=col[j], lw=1.0, label=n)
        ax.scatter(*rel[0, i], color=col[j], marker="o", s=12)
        ax.scatter(*rel[-1, i], color=col[j], marker="s", s=14)
    slots_t = su.slots_m - su.q_des_m  # slots relative to the target when the leader is on q_TL,d
    ax.scatter(slots_t[:, 0], slots_t[:, 1], slots_t[:, 2], color="k", marker="x", s=30, label="slots q_Ti,d")
    ax.plot(rel[:, su.leader, 0], rel[:, su.leader, 1], rel[:, su.leader, 2], color="k", lw=0.8, ls="--",
            label="leader")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    lim = max(120.0, float(np.nanmax(np.abs(rel[:, su.servicers]))))
    for setl in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        setl(-lim, lim)
    ax.set_title(f"{run}: paths relative to the target and its {len(su.radii_m)} structure spheres ({_window(t)})")
    ax.legend(loc="upper left", fontsize=6)
    return _save(fig, path)


def fig_thrust(m: dict, su: SurroundSetup, names: list[str], leader: str, run: str, path: Path) -> str:
    """Figs. 9 and 15-16: thrust norms per craft against their limits."""

    plt = _plt()
    ts = m["t"][:-1]
    col = _colors(len(names))
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax[0].plot(ts, m["leader_n"], color="k", lw=1.0, label=leader)
    ax[0].axhline(su.leader_limit_n, color="r", ls="--", lw=0.8, label=f"limit {su.leader_limit_n:g} N")
    for j, n in enumerate(names):
        ax[1].plot(ts, m["sat_n"][:, j], color=col[j], lw=1.0, label=n)
    for lim in sorted(set(su.servicer_limit_n.tolist())):
        ax[1].axhline(lim, color="r", ls="--", lw=0.8, label=f"limit {lim:g} N")
    ax[0].set_ylabel("leader |u| [N]")
    ax[1].set_ylabel("servicer |u| [N]")
    ax[1].set_xlabel("t [s]")
    ax[0].set_title(f"{run}: thrust norms, applied over each step ({_window(m['t'])})")
    ax[0].legend(loc="upper right")
    ax[1].legend(loc="upper right", ncol=2)
    return _save(fig, path)


# --- the section --------------------------------------------------------------------------------------
def _table(rows: list[tuple[str, str]]) -> str:
    return "<table>" + "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows) + "</table>"


def _run_metrics(ctx: SectionContext) -> tuple[SurroundSetup, dict[str, Any], str, np.ndarray]:
    """(setup, surround_metrics of the run, target id, target positions per truth step) from the recording."""
    tr = ctx.truth
    su = setup_from_config(ctx.config, tr.ids)
    steps, target_pos, _target_vel, tid = read_target(ctx.mcap, ctx.summary.get("run"))
    rows = np.searchsorted(steps, tr.step)
    if not np.array_equal(steps[np.clip(rows, 0, len(steps) - 1)], tr.step):
        raise ValueError("the target's truth does not cover every spacecraft truth step")
    target_pos = target_pos[rows]
    return su, surround_metrics(tr.t_s, tr.position_m, tr.velocity_mps, tr.accel_mps2[:-1], target_pos, su), tid, target_pos


@register_error_metric("p003-surround", applies=lambda cfg: uses_controller(cfg, LEADER_CONTROLLER))
def funnel_ratio(ctx: SectionContext) -> ErrorSeries:
    """max_axis |q~_TL| / funnel half-width per step (eq. 12's bound; >= 1: outside the funnel),
    from the second recorded step (the bound is infinite at t = 0)."""
    m = _run_metrics(ctx)[1]
    return ErrorSeries("leader's TT error over the funnel bound", "ratio", m["t"][1:], m["tt_ratio"])


@register_section("p003-surround", applies=lambda cfg: uses_controller(cfg, LEADER_CONTROLLER))
def surround(ctx: SectionContext) -> SectionResult:
    tr = ctx.truth
    su, m, tid, target_pos = _run_metrics(ctx)
    t = tr.t_s
    ids = tr.ids
    leader = ids[su.leader]
    names = [ids[i] for i in su.servicers]
    run = str(ctx.summary.get("scenario") or (ctx.config.get("run") or {}).get("name") or tr.run)
    k_ratio = int(np.argmax(m["tt_ratio"])) + 1
    s_arg = np.unravel_index(int(np.argmin(m["sphere_surface_m"])), m["sphere_surface_m"].shape)
    p_arg = np.unravel_index(int(np.argmin(m["pair_m"])), m["pair_m"].shape)
    dv = tr.delta_v_mps[-1]
    met: dict[str, Any] = {
        "leader": leader, "target": tid, "servicers": names, "window_s": [float(t[0]), float(t[-1])],
        "tt_err_end_m": m["tt_err_end_m"], "tt_err_end_axis_m": [float(x) for x in m["tt_err_m"][-1]],
        "funnel_end_m": m["funnel_end_m"], "worst_tt_ratio": m["worst_tt_ratio"],
        "worst_tt_ratio_t_s": float(t[k_ratio]), "left_funnel": bool(m["worst_tt_ratio"] >= 1.0),
        "ct_pos_end_m": {n: float(m["ct_pos_m"][-1, j]) for j, n in enumerate(names)},
        "ct_vel_end_mps": {n: float(m["ct_vel_mps"][-1, j]) for j, n in enumerate(names)},
        "ct_pos_end_max_m": m["ct_pos_end_m"], "ct_vel_end_max_mps": m["ct_vel_end_mps"],
        "min_clearance_m": m["min_clearance_m"],
        "min_clearance_at": {"t_s": float(t[s_arg[0]]), "servicer": names[s_arg[1]], "sphere": int(s_arg[2])},
        "min_servicer_distance_m": m["min_pair_end_m"],
        "min_servicer_distance_at": {"t_s": float(t[p_arg[0]]), "pair": [names[p_arg[1]], names[p_arg[2]]]},
        "safe_radius_m": float(su.game.safe_radius_m),
        "peak_thrust_n": {"leader": m["leader_peak_n"], "servicer": m["sat_peak_n"]},
        "thrust_limit_n": {"leader": su.leader_limit_n, "servicer": float(su.servicer_limit_n.max())},
        "controller_limit_n": {"leader": float(su.funnel.max_thrust_n), "servicer": float(su.game.max_thrust_n)},
        "servicer_saturated_frac": m["sat_saturated_frac"],
        "dv_mps": {ids[i]: float(dv[i]) for i in [su.leader, *su.servicers]},
        "mean_dv_servicer_mps": float(dv[su.servicers].mean()) if su.servicers else 0.0,
    }
    out = ctx.out
    figs = [
        (fig_tt(m, run, out / "p003_tt_funnel.png"),
         "Leader's TT error q~_TL per axis (symlog) inside the funnel ±tan(k1(t) π/2) (paper Figs. 6-8); below, "
         "the transformed errors arctan(q~)/k1."),
        (fig_ct(m, names, run, out / "p003_ct_errors.png"),
         "Servicers' position error to their slots and velocity relative to the leader (paper Figs. 13-14)."),
        (fig_paths(tr.position_m, target_pos, su, names, run, t, out / "p003_paths3d.png"),
         "Paths relative to the target around the structure's circumscribed spheres (paper Figs. 10-12); "
         "o start, square end, x the slots."),
        (fig_thrust(m, su, names, leader, run, out / "p003_thrust.png"),
         "Thrust norms |a| m per craft against the force limits (paper Figs. 9, 15-16)."),
    ]
    table = _table([
        ("window", _window(t)),
        ("TT error at the end / funnel", f"{m['tt_err_end_m']:.3g} m / {m['funnel_end_m']:.3g} m"),
        ("worst |TT error| / funnel bound", f"{m['worst_tt_ratio']:.3g} at t = {t[k_ratio]:.1f} s"),
        ("CT position / velocity error at the end (worst)", f"{m['ct_pos_end_m']:.3g} m / {m['ct_vel_end_mps']:.3g} m/s"),
        ("closest servicer-sphere clearance", f"{m['min_clearance_m']:.3g} m ({names[s_arg[1]]}, sphere {s_arg[2]}, "
                                              f"t = {t[s_arg[0]]:.1f} s)"),
        ("closest servicer-servicer distance", f"{m['min_pair_end_m']:.3g} m"),
        ("peak thrust leader / servicers", f"{m['leader_peak_n']:.4g} N of {su.leader_limit_n:g} / "
                                           f"{m['sat_peak_n']:.4g} N of {su.servicer_limit_n.max():g}"),
        ("servicer steps at the limit", f"{100 * m['sat_saturated_frac']:.1f} %"),
        ("mean dV per servicer", f"{met['mean_dv_servicer_mps']:.4g} m/s (leader {dv[su.leader]:.4g} m/s)"),
    ])
    return SectionResult(title="Paper 003: surrounding an escaping target", metrics=met, figures=figs, html=table)
