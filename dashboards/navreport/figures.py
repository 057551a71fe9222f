"""The navigation figures (matplotlib PNGs) of an analysed run."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.figstyle import time_unit
from swarmhil.dashboards.navreport.analysis import H, NavErrors, RunNav, roe_error_magnitudes
from swarmhil.dashboards.navreport.diagnosis import StepSeries
from swarmhil.dashboards.navreport.read import TrackRows

ROE_COMPONENTS = ["a da", "a dl", "a dex", "a dey", "a dix", "a diy"]


def binned(x: np.ndarray, y: np.ndarray, edges: np.ndarray, qs: Sequence[float] = (50, 95)) -> np.ndarray:
    """(len(edges)-1, len(qs)) percentiles of y in bins of x; NaN for empty bins."""
    out = np.full((len(edges) - 1, len(qs)), np.nan)
    ok = np.isfinite(x) & np.isfinite(y)
    b = np.digitize(x[ok], edges) - 1
    yy = y[ok]
    for i in range(len(edges) - 1):
        v = yy[b == i]
        if v.size:
            out[i] = np.percentile(v, qs)
    return out


def _time_edges(t: np.ndarray) -> np.ndarray:
    span = float(t.max() - t.min()) if t.size else 0.0
    width = 900.0 if span > 6 * H else max(60.0, span / 30.0)
    return np.arange(float(t.min()), float(t.max()) + width, width) if t.size else np.array([0.0, 1.0])


def fig_error_time(t_s: np.ndarray, err: NavErrors, used: np.ndarray, path: Path) -> str:
    """Median and 95th percentile over all tracks of the position and ROE errors against time."""
    plt = _plt()
    mags = {"position [m]": np.linalg.norm(err.position_err_m, axis=1), **{
        f"|{k[:-2]}| [m]": v for k, v in roe_error_magnitudes(err.roe_err_m).items()}}
    edges = _time_edges(t_s)
    tu, xl = time_unit(t_s)
    mid = 0.5 * (edges[:-1] + edges[1:]) / tu
    fig, ax = plt.subplots(len(mags), 1, figsize=(8, 1.7 * len(mags)), sharex=True)
    for a, (name, v) in zip(ax, mags.items()):
        for sel, lab, c in ((np.ones_like(used), "all tracks", "C0"), (used, "used by the controller", "C3")):
            q = binned(t_s[sel], v[sel], edges)
            a.plot(mid, q[:, 0], color=c, lw=1.0, label=f"{lab}: median")
            a.plot(mid, q[:, 1], color=c, lw=0.8, ls="--", label=f"{lab}: 95 %")
        a.set_yscale("log")
        a.set_ylabel(name)
    ax[0].legend(loc="upper right", ncol=2)
    ax[0].set_title("Navigation error against truth, all tracked pairs")
    ax[-1].set_xlabel(xl)
    return _save(fig, path)


def fig_nees_time(t_s: np.ndarray, err: NavErrors, used: np.ndarray, path: Path) -> str:
    plt = _plt()
    edges = _time_edges(t_s)
    tu, xl = time_unit(t_s)
    mid = 0.5 * (edges[:-1] + edges[1:]) / tu
    fig, ax = plt.subplots(figsize=(8, 3.2))
    for sel, lab, c in ((np.ones_like(used), "all tracks", "C0"), (used, "used by the controller", "C3")):
        q = binned(t_s[sel], err.nees[sel], edges, (50,))
        ok = np.isfinite(err.nees) & sel
        mean = np.array([np.mean(err.nees[ok][(t_s[ok] >= a) & (t_s[ok] < b)]) if np.any((t_s[ok] >= a) & (t_s[ok] < b))
                         else np.nan for a, b in zip(edges[:-1], edges[1:])])
        ax.plot(mid, mean, color=c, lw=1.0, label=f"{lab}: mean")
        ax.plot(mid, q[:, 0], color=c, lw=0.8, ls=":", label=f"{lab}: median")
    ax.axhline(6.0, color="k", lw=0.8, label="6 (consistent, mean)")
    ax.axhline(5.35, color="0.5", lw=0.6, ls=":", label="5.35 (consistent, median)")
    ax.set_yscale("log")
    ax.set_ylabel("NEES of the ROE (6 dof)")
    ax.set_xlabel(xl)
    ax.legend(loc="upper right", ncol=3)
    ax.set_title("Consistency of the estimator: NEES = e^T P^-1 e")
    return _save(fig, path)


def fig_error_range(err: NavErrors, path: Path) -> str:
    plt = _plt()
    edges = np.linspace(0.0, 550.0, 23)
    mid = 0.5 * (edges[:-1] + edges[1:])
    mags = {"position": np.linalg.norm(err.position_err_m, axis=1), **{
        f"{k[:-2]}": v for k, v in roe_error_magnitudes(err.roe_err_m).items()}}
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for i, (name, v) in enumerate(mags.items()):
        q = binned(err.range_m, v, edges)
        ax.plot(mid, q[:, 0], color=f"C{i}", lw=1.0, label=f"|{name}| median")
        ax.plot(mid, q[:, 1], color=f"C{i}", lw=0.7, ls="--")
    ax.set_yscale("log")
    ax.set_xlabel("true range [m]")
    ax.set_ylabel("error [m] (dashed: 95 %)")
    ax.legend(loc="upper left", ncol=3)
    ax.set_title("Navigation error against true range")
    return _save(fig, path)


def fig_pairs(t_s: np.ndarray, rows: TrackRows, err: NavErrors, path: Path, max_tracks: int = 300) -> str:
    """Position error of each tracked pair over its life (thin lines), the longest tracks first."""
    plt = _plt()
    from matplotlib.collections import LineCollection

    tu, xl = time_unit(t_s)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    life = np.bincount(rows.track, minlength=len(rows.track_names)) if rows.n else np.zeros(0, int)
    keep = np.argsort(life)[::-1][:max_tracks]
    e = np.linalg.norm(err.position_err_m, axis=1)
    segs = []
    order = np.lexsort((rows.step, rows.track))
    starts = np.searchsorted(rows.track[order], keep)
    for c, s0 in zip(keep, starts):
        idx = order[s0:s0 + life[c]]
        ok = np.isfinite(e[idx])
        if ok.sum() > 1:
            segs.append(np.column_stack((t_s[idx][ok] / tu, np.maximum(e[idx][ok], 1e-6))))
    if segs:
        ax.add_collection(LineCollection(segs, linewidths=0.5, alpha=0.5, colors="C0"))
        ax.set_xlim(np.nanmin(t_s) / tu, np.nanmax(t_s) / tu)
        allv = np.concatenate([s[:, 1] for s in segs])
        ax.set_ylim(max(np.percentile(allv, 0.5), 1e-4), allv.max() * 1.5)
    ax.set_yscale("log")
    ax.set_xlabel(xl)
    ax.set_ylabel("|position error| [m]")
    ax.set_title(f"Navigation error per tracked pair ({len(segs)} longest tracks)")
    return _save(fig, path)


def fig_one_track(t_s: np.ndarray, rows: TrackRows, err: NavErrors, path: Path) -> str:
    """ROE error of the longest track with its +-3 sigma envelope (the covariance it reported)."""
    plt = _plt()
    tu, xl = time_unit(t_s)
    fig, ax = plt.subplots(3, 2, figsize=(9, 6), sharex=True)
    if rows.n:
        life = np.bincount(rows.track)
        c = int(np.argmax(life))
        idx = np.flatnonzero(rows.track == c)
        idx = idx[np.argsort(rows.step[idx])]
        th = t_s[idx] / tu
        sig = np.sqrt(np.clip(np.diagonal(rows.covariance_m2[idx], axis1=1, axis2=2), 0, None))
        for i, a in enumerate(ax.T.ravel()):
            a.plot(th, err.roe_err_m[idx, i], lw=0.8, color="C0")
            if np.isfinite(sig[:, i]).any():
                a.fill_between(th, -3 * sig[:, i], 3 * sig[:, i], color="C1", alpha=0.25, lw=0)
            a.set_ylabel(f"{ROE_COMPONENTS[i]} error [m]")
        fig.suptitle(f"Longest track {rows.track_names[c]}: ROE error and +-3 sigma")
    for a in ax[-1]:
        a.set_xlabel(xl)
    return _save(fig, path)


def nav_figures(nav: RunNav, out: Path, prefix: str = "") -> list[tuple[str, str]]:
    """The navigation figures of a run written into out: (PNG name, caption) pairs."""
    if not nav.rows.n:
        return []
    ok = nav.err.truth_row >= 0
    t_s = np.where(ok, nav.truth.t_s[np.clip(nav.err.truth_row, 0, None)], np.nan)
    figs = [
        (fig_pairs(t_s, nav.rows, nav.err, out / f"{prefix}pairs.png"),
         "Position error of each tracked pair (a track of observer j associated with the nearest true k)."),
        (fig_error_time(t_s, nav.err, nav.rows.used, out / f"{prefix}error_time.png"),
         "Median and 95th percentile, in 15-min bins, of the position and ROE errors; red: the tracks "
         "the controller acted on."),
        (fig_error_range(nav.err, out / f"{prefix}error_range.png"), "Errors against the true range."),
        (fig_one_track(t_s, nav.rows, nav.err, out / f"{prefix}longest_track.png"),
         "ROE error of the longest track and the +-3 sigma of its reported covariance."),
    ]
    if np.isfinite(nav.err.nees).any():
        figs.append((fig_nees_time(t_s, nav.err, nav.rows.used, out / f"{prefix}nees_time.png"),
                     "NEES of the ROE estimate (6 dof): mean 6 and median 5.35 when consistent."))
    return figs



def fig_steps(s: StepSeries, split_t_s: Sequence[float], path: Path) -> str:
    """Per truth step (dashboards/navreport/diagnosis.py): components of the visibility digraph,
    missed / lost / false / swapped tracks, and the median error of each layer; splits marked."""
    plt = _plt()
    tu, xl = time_unit(s.t_s)
    t = s.t_s / tu
    panels = [("components", None)] + [(q, u) for q, u in (("range_m", "range [m]"), ("velocity_mps", "velocity [m/s]"),
                                                          ("da_m", "|a da| [m]"), ("de_m", "|a de| [m]"))
                                      if any(q in qs for qs in s.layers.values())]
    fig, ax = plt.subplots(len(panels) + 1, 1, figsize=(8, 1.6 * (len(panels) + 1)), sharex=True)
    a = ax[0]
    a.step(t, s.components, where="post", color="k", lw=1.0, label="components (visibility)")
    a.set_ylabel("components")
    a.set_ylim(0.5, max(2, int(s.components.max()) if s.components.size else 1) + 0.5)
    a = ax[1]
    for name, c in (("missed", "C0"), ("lost", "C3"), ("false_tracks", "C1"), ("swaps", "C4"), ("duplicate_tracks", "C2"),
                    ("breaks", "C5")):
        v = getattr(s, name)
        if v.any() and s.tracks_recorded:
            a.step(t, v, where="post", color=c, lw=0.9, label=name.replace("_", " "))
    a.set_ylabel("count per step")
    if a.get_legend_handles_labels()[0]:
        a.legend(loc="upper right", ncol=5)
    a.set_title("Against truth, per step: visible pairs without a matched track, false tracks, swaps")
    for a, (q, label) in zip(ax[2:], panels[1:]):
        for i, (layer, qs) in enumerate(s.layers.items()):
            if q in qs and np.isfinite(qs[q]["median"]).any():
                a.plot(t, np.maximum(qs[q]["median"], 1e-9), color=f"C{i}", lw=0.8, label=f"{layer}: median")
                a.plot(t, np.maximum(qs[q]["max"], 1e-9), color=f"C{i}", lw=0.5, ls=":", label=f"{layer}: max")
        a.set_yscale("log")
        a.set_ylabel(label)
        if a.get_legend_handles_labels()[0]:
            a.legend(loc="upper right", ncol=3)
    for a in ax:
        for ts in split_t_s:
            a.axvline(ts / tu, color="C3", lw=0.6, alpha=0.6)
    ax[-1].set_xlabel(xl)
    return _save(fig, path)
