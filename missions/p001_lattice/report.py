"""Paper 001 report section (issue 13): the Tersoff-Brenner hexagon at GEO, in the spirit of Figs. 2-5.

Applies when the run flew controller "p001-lattice". Everything is computed from the recording:
ctx.truth (positions, velocities, commanded accelerations in the CW/LVLH frame of the reference
point) and ctx.config (the resolved configuration: the controller's params give the radii of the
three spheres, l, u_max and the desired phase; the actuator table gives the plant's limit).

This module imports the room's contract (missions/p001_lattice/contract.py: eq. 16, the geometric
hexagon test, structure_name, and the parameter model with the paper's defaults for any parameter
the scenario left unset): numpy-only functions of arrays, no flight-software state.

Metrics (summary.json["metrics"]["p001-formation"]):
  gathering      per agent, the first recorded time |r| < r_middle (100 m) and |r| < r_inner (15 m)
  speed          max |v| over agents and steps (paper: < 0.18 m/s)
  thrust         max |a| of the applied command against the limits (controller's and actuator's)
  closest_approach  smallest pair distance at the recorded steps, its pair and time
  final          structure_name, check_hexagon (side, centre, phase, planarity), eq. 16 at the end
  formed         first time from which check_hexagon holds at every recorded step to the end
  eq16           at the end, minimum and its time (the series is figure 4)
"""
from __future__ import annotations

import html
from dataclasses import fields
from typing import Any

import numpy as np

from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section, uses_controller
from swarmhil.missions.p001_lattice.contract import (
    CONTROLLER,
    LatticeParams,
    check_hexagon,
    hexagon_vertices,
    mean_relative_error,
    structure_name,
)

PAPER_V_MAX_MPS = 0.18
PAPER_EQ16 = 0.0125
PAPER_T_FORM_S = 25000.0


def lattice_params(cfg: dict[str, Any]) -> LatticeParams:
    """The room's parameters of the run: the recorded [controller] params over the paper's defaults."""
    known = {f.name for f in fields(LatticeParams)}
    params = (cfg.get("controller") or {}).get("params") or {}
    return LatticeParams.from_dict({k: v for k, v in params.items() if k in known})


def _f(x: Any) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def first_entry(r_m: np.ndarray, t_s: np.ndarray, radius_m: float) -> list[float | None]:
    """Per agent (columns of r_m), the first recorded time with |r| < radius (None: never)."""
    inside = r_m < radius_m
    return [float(t_s[np.argmax(inside[:, i])]) if inside[:, i].any() else None for i in range(r_m.shape[1])]


def formation_metrics(t_s: np.ndarray, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, ids: list[str],
                      p: LatticeParams, actuator_limit_mps2: float | None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The section's numbers and the per-step series behind the figures."""
    r = np.linalg.norm(pos, axis=2)
    speed = np.linalg.norm(vel, axis=2)
    thrust = np.linalg.norm(acc, axis=2)
    eq16 = np.array([mean_relative_error(x, p.side_m) for x in pos])
    d = np.linalg.norm(pos[:, :, None, :] - pos[:, None, :, :], axis=3)
    iu = np.triu_indices(len(ids), 1)
    pair_d = d[:, iu[0], iu[1]]
    k, q = np.unravel_index(int(np.argmin(pair_d)), pair_d.shape)
    hexa_ok = np.array([check_hexagon(x, p.side_m).is_hexagon for x in pos])
    formed = None
    if hexa_ok[-1]:
        bad = np.flatnonzero(~hexa_ok)
        formed = float(t_s[bad[-1] + 1]) if bad.size else float(t_s[0])
    final = pos[-1]
    hx = check_hexagon(final, p.side_m)
    ki, vi = np.unravel_index(int(np.argmax(speed)), speed.shape)
    ai = np.unravel_index(int(np.argmax(thrust)), thrust.shape)
    limit = p.max_accel_mps2 if actuator_limit_mps2 is None else min(p.max_accel_mps2, actuator_limit_mps2)
    mid, inner = first_entry(r, t_s, p.r_middle_m), first_entry(r, t_s, p.r_inner_m)

    def span(v: list[float | None]) -> list[float] | None:
        got = [x for x in v if x is not None]
        return [min(got), max(got)] if got else None

    met = {
        "params": {"side_m": p.side_m, "r_outer_m": p.r_outer_m, "r_middle_m": p.r_middle_m, "r_inner_m": p.r_inner_m,
                   "phase_deg": p.phase_deg, "x_shift_m": p.x_shift_m, "t_natural_s": p.t_natural_s,
                   "t_desire_s": p.t_desire_s, "max_accel_mps2": p.max_accel_mps2},
        "t_end_s": float(t_s[-1]),
        "gathering": {
            "release_radius_m": [float(x) for x in r[0]],
            "enter_middle_s": dict(zip(ids, mid)),
            "enter_inner_s": dict(zip(ids, inner)),
            "enter_middle_span_s": span(mid),
            "enter_inner_span_s": span(inner),
            "radius_end_m": [float(x) for x in r[-1]],
        },
        "speed": {"max_mps": float(speed.max()), "agent": ids[vi], "t_s": float(t_s[ki]),
                  "paper_bound_mps": PAPER_V_MAX_MPS, "below_paper_bound": bool(speed.max() < PAPER_V_MAX_MPS)},
        "thrust": {"max_mps2": float(thrust.max()), "agent": ids[ai[1]], "t_s": float(t_s[ai[0]]),
                   "limit_mps2": float(limit), "controller_limit_mps2": p.max_accel_mps2,
                   "actuator_limit_mps2": actuator_limit_mps2,
                   "within_limit": bool(thrust.max() <= limit * (1 + 1e-9)),
                   "saturated_steps": int((thrust >= limit * (1 - 1e-6)).sum())},
        "closest_approach": {"distance_m": float(pair_d[k, q]), "pair": [ids[iu[0][q]], ids[iu[1][q]]],
                             "t_s": float(t_s[k])},
        "final": {
            "structure": structure_name(final, p.side_m),
            "is_hexagon": hx.is_hexagon,
            "ring": hx.ring,
            "side_min_m": hx.side_min_m, "side_max_m": hx.side_max_m,
            "side_mean_m": float(np.mean(np.sort(d[-1] + np.diag([np.inf] * len(ids)), axis=1)[:, :2])),
            "angle_min_deg": hx.angle_min_deg, "angle_max_deg": hx.angle_max_deg,
            "thickness_m": hx.thickness_m, "normal_x": hx.normal_x,
            "centre_m": [float(c) for c in hx.centre_m],
            "centre_offset_from_origin_m": float(np.linalg.norm(hx.centre_m)),
            "phase_deg": hx.phase_deg,
            "max_abs_x_m": float(np.abs(final[:, 0]).max()),
            "eq16": hx.eq16,
        },
        "formed_s": formed,
        "formed_before_paper_bound": None if formed is None else formed < PAPER_T_FORM_S,
        "eq16": {"end": float(eq16[-1]), "min": float(eq16.min()), "t_min_s": float(t_s[int(np.argmin(eq16))]),
                 "paper": PAPER_EQ16},
    }
    series = {"r": r, "speed": speed, "thrust": thrust, "eq16": eq16, "min_pair": pair_d.min(axis=1)}
    return met, series


# --- figures ----------------------------------------------------------------------------------------------
def _sphere(ax, radius: float, color: str, label: str) -> None:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 25), np.linspace(0, np.pi, 13))
    ax.plot_wireframe(radius * np.cos(u) * np.sin(v), radius * np.sin(u) * np.sin(v), radius * np.cos(v),
                      color=color, lw=0.3, alpha=0.35, label=label)


def fig_paths(t_s, pos, ids, p: LatticeParams, met, path) -> str:
    """Fig. 2: 3-D paths in the CW frame with the three spheres; left the whole run, right inside r_middle."""

    plt = _plt()
    cols = _colors(len(ids))
    fig = plt.figure(figsize=(12, 5.5))
    for j, (lim, spheres, sub) in enumerate([
        (max(p.r_outer_m, float(np.nanmax(np.abs(pos)))) * 1.05, [(p.r_outer_m, "0.6", "r_outer"),
                                                                 (p.r_middle_m, "C1", "r_middle")], "whole run"),
        (p.r_middle_m * 1.05, [(p.r_middle_m, "C1", "r_middle"), (p.r_inner_m, "C2", "r_inner")],
         f"inside r_middle = {p.r_middle_m:g} m"),
    ]):
        ax = fig.add_subplot(1, 2, j + 1, projection="3d")
        for rad, c, lab in spheres:
            _sphere(ax, rad, c, f"{lab} = {rad:g} m")
        for i, sid in enumerate(ids):
            x = pos[:, i]
            keep = np.all(np.abs(x) <= lim, axis=1) if j else slice(None)
            ax.plot(x[keep, 1], x[keep, 2], x[keep, 0], color=cols[i], lw=0.8, label=sid if j == 0 else None)
            ax.plot([x[-1, 1]], [x[-1, 2]], [x[-1, 0]], "o", color=cols[i], ms=3)
            if j == 0:
                ax.plot([x[0, 1]], [x[0, 2]], [x[0, 0]], "^", color=cols[i], ms=4)
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-lim, lim)
        ax.set_zlim(-lim, lim)
        ax.set_xlabel("y along-track [m]")
        ax.set_ylabel("z cross-track [m]")
        ax.set_zlabel("x radial [m]")
        ax.set_title(f"Paths, {sub} (0-{t_s[-1]:.0f} s)")
        if j == 0:
            ax.legend(loc="upper left", fontsize=6)
    fig.suptitle(f"Paper 001 Fig. 2: gathering of {len(ids)} spacecraft; final structure "
                 f"{met['final']['structure']}")
    return _save(fig, path)


def fig_pattern(pos_end, ids, p: LatticeParams, met, path) -> str:
    """Fig. 3: the final pattern in the yz-plane with the desired vertices and the bonds (< 1.3 l)."""

    plt = _plt()
    cols = _colors(len(ids))
    want = hexagon_vertices(p.side_m, p.phase_deg, p.x_shift_m)
    fig, ax = plt.subplots(figsize=(6.5, 6))
    d = np.linalg.norm(pos_end[:, None] - pos_end[None], axis=2)
    for a in range(len(ids)):
        for b in range(a + 1, len(ids)):
            if d[a, b] < 1.3 * p.side_m:
                ax.plot(pos_end[[a, b], 1], pos_end[[a, b], 2], color="0.5", lw=0.8)
    ring = np.vstack([want, want[:1]])
    ax.plot(ring[:, 1], ring[:, 2], "k--", lw=0.8, label=f"desired hexagon (l = {p.side_m:g} m, {p.phase_deg:g} deg)")
    ax.plot(want[:, 1], want[:, 2], "kx", ms=7)
    for i, sid in enumerate(ids):
        ax.plot(pos_end[i, 1], pos_end[i, 2], "o", color=cols[i], ms=8, label=f"{sid} (x = {pos_end[i, 0]:.2f} m)")
    c = met["final"]["centre_m"]
    ax.plot(c[1], c[2], "+", color="C3", ms=10, label=f"centre ({c[1]:.2f}, {c[2]:.2f}) m")
    pts = np.vstack([pos_end[:, 1:], want[:, 1:]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = 0.6 * float(max(hi - lo)) + 1.0
    mid = (lo + hi) / 2
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_aspect("equal")
    ax.set_xlabel("y along-track [m]")
    ax.set_ylabel("z cross-track [m]")
    f = met["final"]
    ax.set_title(f"Paper 001 Fig. 3: pattern at {met['t_end_s']:.0f} s: {f['structure']}, sides "
                 f"{f['side_min_m']:.2f}-{f['side_max_m']:.2f} m,\nphase {f['phase_deg']:.1f} deg, eq. 16 = {f['eq16']:.4f}")
    ax.legend(loc="upper left", fontsize=6)
    return _save(fig, path)


def fig_speed_accel(t_s, series, ids, met, path) -> str:
    """Fig. 4: speed and commanded acceleration of each agent over time, with the paper's bounds."""

    plt = _plt()
    cols = _colors(len(ids))
    fig, ax = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for i, sid in enumerate(ids):
        ax[0].plot(t_s, series["speed"][:, i], color=cols[i], lw=0.7, label=sid)
        ax[1].plot(t_s, series["thrust"][:, i] * 1e3, color=cols[i], lw=0.7)
    ax[0].axhline(PAPER_V_MAX_MPS, color="r", ls="--", lw=0.8, label=f"paper: < {PAPER_V_MAX_MPS} m/s")
    ax[1].axhline(met["thrust"]["limit_mps2"] * 1e3, color="r", ls="--", lw=0.8, label="limit")
    span = met["gathering"]["enter_middle_span_s"]
    for a in ax:
        if span:
            a.axvspan(span[0], span[1], color="C1", alpha=0.15, lw=0)
    ax[0].set_ylabel("|v| [m/s]")
    ax[0].set_title(f"Paper 001 Fig. 4: speeds (max {met['speed']['max_mps']:.3f} m/s) and accelerations "
                    f"(max {met['thrust']['max_mps2'] * 1e3:.2f} mm/s^2)\norange band: agents enter r_middle")
    ax[0].legend(loc="upper right", ncol=2)
    ax[1].set_ylabel("|a| [mm/s^2]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(loc="upper right")
    return _save(fig, path)


def fig_eq16(t_s, series, met, path) -> str:
    """Fig. 5: eq. 16 over time (log scale), from the first agent entering r_middle when there is one."""

    plt = _plt()
    span = met["gathering"]["enter_middle_span_s"]
    fig, ax = plt.subplots(2, 1, figsize=(8, 5.5))
    ax[0].semilogy(t_s, series["eq16"], color="C0", lw=0.8)
    ax[0].axhline(PAPER_EQ16, color="r", ls="--", lw=0.8, label=f"paper: {PAPER_EQ16}")
    if met["formed_s"] is not None:
        ax[0].axvline(met["formed_s"], color="C2", lw=0.8, label=f"hexagon from {met['formed_s']:.0f} s")
    ax[0].set_ylabel("eq. 16")
    ax[0].set_title(f"Paper 001 Fig. 5: mean relative error (eq. 16), end {met['eq16']['end']:.4f}")
    ax[0].legend(loc="upper right")
    t0 = span[0] if span else t_s[0]
    sel = t_s >= t0
    ax[1].semilogy(t_s[sel], series["eq16"][sel], color="C0", lw=0.8, label="eq. 16")
    ax[1].semilogy(t_s[sel], series["min_pair"][sel] / met["params"]["side_m"], color="C3", lw=0.7,
                   label="closest pair / l")
    ax[1].axhline(PAPER_EQ16, color="r", ls="--", lw=0.8)
    ax[1].set_xlabel("time [s]")
    ax[1].set_title(f"from {t0:.0f} s" + (" (first agent inside r_middle)" if span else ""))
    ax[1].legend(loc="upper right")
    return _save(fig, path)


def _table(met: dict[str, Any], ids: list[str]) -> str:
    def fmt(v: float | None) -> str:
        return "never" if v is None else f"{v:.0f}"

    g = met["gathering"]
    p = met["params"]
    rows = "".join(f"<tr><td>{html.escape(s)}</td><td>{g['release_radius_m'][i]:.1f}</td>"
                   f"<td>{fmt(g['enter_middle_s'][s])}</td><td>{fmt(g['enter_inner_s'][s])}</td>"
                   f"<td>{g['radius_end_m'][i]:.2f}</td></tr>" for i, s in enumerate(ids))
    f, sp, th, ca = met["final"], met["speed"], met["thrust"], met["closest_approach"]
    head = [
        ("final structure", f"{f['structure']} (hexagon test: {'yes' if f['is_hexagon'] else 'no'})"),
        ("side [m]", f"{f['side_min_m']:.3f}-{f['side_max_m']:.3f} (l = {p['side_m']:g})"),
        ("centre [m], |x| max [m]", "(" + ", ".join(f"{c:.2f}" for c in f["centre_m"]) + f"), {f['max_abs_x_m']:.3f}"),
        ("phase [deg]", f"{f['phase_deg']:.1f} (desired {p['phase_deg']:g})"),
        ("eq. 16 at the end (paper 0.0125)", f"{f['eq16']:.4f}"),
        ("hexagon held from [s] (paper < 25,000)", fmt(met["formed_s"])),
        ("max speed [m/s] (paper < 0.18)", f"{sp['max_mps']:.4f} ({html.escape(sp['agent'])} at {sp['t_s']:.0f} s)"),
        ("max |a| [m/s^2] / limit", f"{th['max_mps2']:.3g} / {th['limit_mps2']:.3g} ({th['saturated_steps']} saturated agent-steps)"),
        ("closest approach [m]", f"{ca['distance_m']:.2f} ({html.escape('-'.join(ca['pair']))} at {ca['t_s']:.0f} s)"),
    ]
    top = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in head)
    return (f"<table>{top}</table><p>Gathering timeline: first recorded time inside r_middle = {p['r_middle_m']:g} m "
            f"and r_inner = {p['r_inner_m']:g} m.</p><table><tr><th>agent</th><th>|r| at release [m]</th>"
            f"<th>inside r_middle [s]</th><th>inside r_inner [s]</th><th>|r| at the end [m]</th></tr>{rows}</table>")


@register_section("p001-formation", applies=lambda cfg: uses_controller(cfg, CONTROLLER))
def formation(ctx: SectionContext) -> SectionResult:
    truth = ctx.truth
    p = lattice_params(ctx.config)
    act = (ctx.config.get("actuator") or {}).get("max_accel_mps2")
    alive = truth.alive.all(axis=1)
    t_s, pos, vel, acc = truth.t_s[alive], truth.position_m[alive], truth.velocity_mps[alive], truth.accel_mps2[alive]
    met, series = formation_metrics(t_s, pos, vel, acc, truth.ids, p, None if act is None else float(act))
    out = ctx.out
    figs = [
        (fig_paths(t_s, pos, truth.ids, p, met, out / "p001_paths.png"),
         f"3-D paths in the CW frame with the spheres r_outer, r_middle, r_inner = {p.r_outer_m:g}, {p.r_middle_m:g}, "
         f"{p.r_inner_m:g} m (paper Fig. 2); triangles: release, dots: end."),
        (fig_pattern(pos[-1], truth.ids, p, met, out / "p001_pattern.png"),
         "Final pattern in the yz-plane, bonds shorter than 1.3 l, and the desired vertices (paper Fig. 3)."),
        (fig_speed_accel(t_s, series, truth.ids, met, out / "p001_speed_accel.png"),
         "Speed and commanded acceleration (after the actuator limit) of each agent (paper Fig. 4)."),
        (fig_eq16(t_s, series, met, out / "p001_eq16.png"),
         "Eq. 16 over time (paper Fig. 5); lower panel from the first entry into r_middle with the closest pair / l."),
    ]
    return SectionResult(title="Paper 001: formation (Tersoff-Brenner hexagon)", metrics=met, figures=figs,
                         html=_table(met, truth.ids))
