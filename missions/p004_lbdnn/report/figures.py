"""Paper 004's report, figures (matplotlib) like the paper's: the servicers' paths relative to the
defunct craft (Fig. 2: 3D over the first PATH_WINDOW_S, with the three planar projections over the
whole run), the tracking errors (Fig. 4) and the control effort with the cumulative Δv (not a
figure of the paper), from the arrays and metrics of analysis.py `compute`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.figstyle import colors as _colors
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.missions.p004_lbdnn.report.analysis import STEADY_FROM_S, TRACK_LEVEL_M

PATH_WINDOW_S = 60.0      # Fig. 2 shows the first 60 s


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
