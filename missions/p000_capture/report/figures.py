"""Paper 000's report, figures (matplotlib): the paths around the target ellipsoid, the signed
distance to the TRUE surface, the pair distances, the messages sent and the trigger instants, the
attitude errors (Fig. 5) and the agents' estimates against the truth (Figs. 7 and 12), from the
arrays of read.py and analysis.py.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.missions.p000_capture.contract import dcm
from swarmhil.missions.p000_capture.report.analysis import window_label
from swarmhil.missions.p000_capture.report.read import CaptureRecording


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
    ax.set_title(f"{run}:\npaths relative to the target centre ({window_label(t)}); target at the end")
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

