"""HTML + PNG reports of a run and of a sweep, in the spirit of paper 002's Figs. 7-22 and 30-31.

`write_report(run_dir)` reads run_dir/run.mcap (truth only, dashboards/truth_io.py), computes the
metrics (dashboards/metrics.py), adds them to run_dir/summary.json under "metrics" and writes
run_dir/report/index.html with one PNG per figure. `write_sweep_report(sweep_dir, cases)` does the
same for a parameter sweep (dV and connectivity against the parameter, Figs. 30-31).
"""
from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from dashboards.metrics import D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN, SwarmMetrics, compute_metrics, relative_to_com
from dashboards.run_config import camera_from_config, run_config
from dashboards.truth_io import TruthArrays, read_truth
from plant.sensors import CameraGeometry

H = 3600.0
SERIES = "metrics_series.npz"  # per-step series a sweep report overlays


def _plt():
    from bus.optional import require

    matplotlib = require("matplotlib", "the report's figures")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"figure.dpi": 100, "savefig.dpi": 100, "axes.grid": True, "grid.alpha": 0.3,
                         "font.size": 9, "legend.fontsize": 7})
    return plt


def _colors(n: int) -> list:
    plt = _plt()
    cmap = plt.get_cmap("tab20")
    return [cmap(i % 20) for i in range(n)]


def _save(fig, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path)
    _plt().close(fig)
    return path.name


# --- run figures --------------------------------------------------------------------------------------
def fig_components(m: SwarmMetrics, n: int, path: Path, title: str = "") -> str:
    """Fig. 10 / 31: weakly connected components of the visibility digraph over time."""
    plt = _plt()
    fig, ax = plt.subplots(2, 1, figsize=(8, 4.5), sharex=True)
    th = m.t_s / H
    ax[0].step(th, m.n_components, where="post", color="C0", label="digraph of the step")
    ax[0].step(th, m.n_components_orbit, where="post", color="C2", ls="--", lw=0.9,
               label="union of the digraphs over the last orbit")
    ax[0].legend(loc="upper left")
    ax[0].set_ylabel("weakly connected\ncomponents")
    ax[0].set_ylim(0, max(3, m.n_components.max() + 1))
    ax[0].set_title(title or "Swarm integrity (paper 002 Figs. 10, 31)")
    ax[1].step(th, m.largest, where="post", color="C1")
    ax[1].axhline(n, color="k", lw=0.8, ls="--")
    ax[1].set_ylabel("largest component\n(spacecraft)")
    ax[1].set_ylim(0, n + 1)
    ax[1].set_xlabel("time [h]")
    return _save(fig, path)


def _circle_layout(n: int) -> np.ndarray:
    ang = np.pi / 2 - 2 * np.pi * np.arange(n) / n
    return np.stack([np.cos(ang), np.sin(ang)], axis=1)


def fig_digraph(truth: TruthArrays, m: SwarmMetrics, row: int, path: Path, label: str) -> str:
    """Figs. 8-9 / 11: the visibility digraph (j -> k: j sees k) in LVLH and as a graph plot."""
    plt = _plt()
    vis = m.vis[row]
    pos = relative_to_com(truth.position_m[row:row + 1], truth.alive[row:row + 1])[0]
    ids = truth.ids
    n = len(ids)
    comp_colors = _colors(max(1, m.n_components[row]))
    from scipy.sparse.csgraph import connected_components

    _nc, labels = connected_components(vis, directed=True, connection="weak")
    node_c = [comp_colors[lab % len(comp_colors)] for lab in labels]
    fig, ax = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [1.6, 1]})
    a = ax[0]
    for j, k in zip(*np.nonzero(vis)):
        a.annotate("", xy=(pos[k, 1], pos[k, 0]), xytext=(pos[j, 1], pos[j, 0]),
                   arrowprops=dict(arrowstyle="->", color="0.5", lw=0.7, ls=":"))
    a.scatter(pos[:, 1], pos[:, 0], c=node_c, s=30, zorder=3, edgecolors="k", linewidths=0.5)
    for i, sid in enumerate(ids):
        a.annotate(sid, (pos[i, 1], pos[i, 0]), fontsize=6, xytext=(2, 3), textcoords="offset points")
    a.set_xlabel("along-track y - y_com [m]")
    a.set_ylabel("radial x - x_com [m]")
    a.set_title(f"{label}: positions (LVLH, centre of mass), arrows j -> k when j sees k")
    b = ax[1]
    order = np.argsort(truth.position_m[row, :, 1])[::-1]  # leader at the top, then clockwise backwards
    xy = np.empty((n, 2))
    xy[order] = _circle_layout(n)
    for j, k in zip(*np.nonzero(vis)):
        b.annotate("", xy=xy[k], xytext=xy[j], arrowprops=dict(arrowstyle="-|>", color="0.4", lw=0.8,
                                                               shrinkA=7, shrinkB=7))
    b.scatter(xy[:, 0], xy[:, 1], c=node_c, s=160, zorder=3, edgecolors="k", linewidths=0.5)
    for i, sid in enumerate(ids):
        b.text(xy[i, 0] * 1.16, xy[i, 1] * 1.16, sid, ha="center", va="center", fontsize=7)
    b.set_xlim(-1.35, 1.35)
    b.set_ylim(-1.3, 1.3)
    b.set_aspect("equal")
    b.axis("off")
    b.set_title(f"{label}: {m.n_components[row]} weak component(s), {int(vis.sum())} edges\n"
                "(nodes ordered by along-track position)")
    return _save(fig, path)


_ROE_NAMES = ["a da", "a dl", "a dex", "a dey", "a dix", "a diy"]


def fig_roe_com(truth: TruthArrays, pair: tuple[int, int], path: Path, fig_no: str) -> str:
    """Figs. 12-14: ROE of each spacecraft relative to the swarm centre of mass."""
    plt = _plt()
    roe = relative_to_com(truth.roe_m, truth.alive)
    th = truth.t_s / H
    cols = _colors(truth.n_bodies)
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for a, c in zip(ax, pair):
        for i in range(truth.n_bodies):
            a.plot(th, roe[:, i, c], color=cols[i], lw=0.8)
        a.set_ylabel(f"{_ROE_NAMES[c]} - com [m]")
    ax[0].set_title(f"ROE relative to the swarm centre of mass (paper 002 Fig. {fig_no})")
    ax[1].set_xlabel("time [h]")
    return _save(fig, path)


def fig_separation(m: SwarmMetrics, field: str, threshold: float, ylabel: str, title: str, path: Path,
                   extra: str | None = None) -> str:
    """Figs. 15-17: separation of each spacecraft from its closest visible neighbour."""
    plt = _plt()
    y = getattr(m.closest, field)
    th = m.t_s / H
    cols = _colors(y.shape[1])
    fig, ax = plt.subplots(figsize=(8, 3.8))
    for i in range(y.shape[1]):
        ax.plot(th, y[:, i], color=cols[i], lw=0.7)
    lo = float(np.nanmin(y)) if np.isfinite(y).any() else 0.0
    if extra is not None:
        e = getattr(m.closest, extra)
        with np.errstate(all="ignore"):
            emin = np.where(np.isfinite(e).any(axis=1), np.nanmin(np.where(np.isfinite(e), e, np.inf), axis=1), np.nan)
        ax.plot(th, emin, color="k", lw=0.8, ls=":", label="min over spacecraft of a(|dl|-2|de|)")
        ax.legend(loc="upper right")
        if np.isfinite(emin).any():
            lo = min(lo, float(np.nanmin(emin)))
    ax.axhline(threshold, color="r", ls="--", lw=1.0)
    ax.axvspan(m.t_s[m.steady][0] / H, th[-1], color="0.9", zorder=0)
    ax.set_ylim(bottom=min(0.0, lo))
    ax.set_xlabel("time [h]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    return _save(fig, path)


def fig_parallelism(m: SwarmMetrics, path: Path) -> str:
    """Fig. 18: parallelism |de.di|/(|de||di|) of visible pairs."""
    plt = _plt()
    th = m.t_s / H
    cols = _colors(m.closest.parallelism.shape[1])
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for i in range(m.closest.parallelism.shape[1]):
        ax[0].plot(th, m.closest.parallelism[:, i], color=cols[i], lw=0.7)
    ax[0].axhline(PARALLEL_MIN, color="r", ls="--", lw=1.0)
    ax[0].set_ylabel("closest visible\nneighbour")
    ax[0].set_title("Parallelism of de and di (paper 002 Fig. 18)")
    pp = m.pair_parallelism.reshape(m.t_s.size, -1)
    with np.errstate(all="ignore"):
        has = np.isfinite(pp).any(axis=1)
        lo = np.where(has, np.nanmin(np.where(np.isfinite(pp), pp, np.inf), axis=1), np.nan)
        frac = np.where(has, np.nansum(pp >= PARALLEL_MIN, axis=1) / np.maximum(np.isfinite(pp).sum(axis=1), 1), np.nan)
    ax[1].plot(th, lo, color="C3", lw=0.8, label="min over visible pairs")
    ax[1].plot(th, frac, color="C0", lw=0.8, label=f"fraction of visible pairs >= {PARALLEL_MIN}")
    ax[1].axhline(PARALLEL_MIN, color="r", ls="--", lw=1.0)
    ax[1].set_ylim(-0.02, 1.02)
    ax[1].legend(loc="lower right")
    ax[1].set_xlabel("time [h]")
    return _save(fig, path)


def fig_accel(m: SwarmMetrics, ids: list[str], path: Path) -> str:
    """Fig. 19: control acceleration of each spacecraft."""
    plt = _plt()
    th = m.t_s / H
    cols = _colors(len(ids))
    fig, ax = plt.subplots(figsize=(8, 3.8))
    for i in range(len(ids)):
        ax.plot(th, m.accel_mps2[:, i] * 1e3, color=cols[i], lw=0.6)
    ax.set_xlabel("time [h]")
    ax.set_ylabel("|a| [mm/s^2]")
    ax.set_title("Control acceleration of each spacecraft (paper 002 Fig. 19)")
    return _save(fig, path)


def fig_dv(m: SwarmMetrics, ids: list[str], path: Path) -> str:
    """Fig. 20: cumulative dV of each spacecraft and of the swarm."""
    plt = _plt()
    th = m.t_s / H
    cols = _colors(len(ids))
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for i, sid in enumerate(ids):
        ax[0].plot(th, m.delta_v_mps[:, i], color=cols[i], lw=0.8, label=sid)
    ax[0].set_ylabel("dV per spacecraft [m/s]")
    ax[0].set_title("Cumulative dV (paper 002 Fig. 20)")
    if len(ids) <= 20:
        ax[0].legend(ncol=1, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=6)
    ax[1].plot(th, m.delta_v_mps.sum(axis=1), color="k")
    ax[1].axvspan(m.t_s[m.steady][0] / H, th[-1], color="0.9", zorder=0)
    ax[1].set_ylabel("total dV [m/s]")
    ax[1].set_xlabel("time [h]")
    return _save(fig, path)


def fig_along_track(truth: TruthArrays, path: Path, title: str) -> str:
    """Figs. 7 / 21: along-track position relative to the swarm centre of mass."""
    plt = _plt()
    pos = relative_to_com(truth.position_m, truth.alive)
    th = truth.t_s / H
    cols = _colors(truth.n_bodies)
    fig, ax = plt.subplots(figsize=(8, 3.8))
    for i in range(truth.n_bodies):
        ax.plot(th, pos[:, i, 1] / 1e3, color=cols[i], lw=0.8)
    ax.set_xlabel("time [h]")
    ax.set_ylabel("y - y_com [km]")
    ax.set_title(title)
    return _save(fig, path)


def fig_projections(truth: TruthArrays, path: Path, last_s: float | None = None) -> str:
    """Fig. 22: cross-track (x-z) and in-orbit (y-x) projections relative to the centre of mass."""
    plt = _plt()
    pos = relative_to_com(truth.position_m, truth.alive)
    sel = slice(None) if last_s is None else truth.t_s >= truth.t_s[-1] - last_s
    p = pos[sel]
    cols = _colors(truth.n_bodies)
    fig, ax = plt.subplots(2, 1, figsize=(8, 8))
    for i in range(truth.n_bodies):
        ax[0].plot(p[:, i, 2], p[:, i, 0], color=cols[i], lw=0.6)
        ax[1].plot(p[:, i, 1], p[:, i, 0], color=cols[i], lw=0.6)
        ax[1].plot(p[-1, i, 1], p[-1, i, 0], "o", color=cols[i], ms=3)
    span = "whole run" if last_s is None else f"last {last_s / H:.1f} h"
    ax[0].set_xlabel("cross-track z - z_com [m]")
    ax[0].set_ylabel("radial x - x_com [m]")
    ax[0].set_aspect("equal", adjustable="datalim")
    ax[0].set_title(f"Cross-track projection ({span}; paper 002 Fig. 22 upper)")
    ax[1].set_xlabel("along-track y - y_com [m]")
    ax[1].set_ylabel("radial x - x_com [m]")
    ax[1].set_title(f"In-orbit projection ({span}; paper 002 Fig. 22 lower), dots at the end")
    return _save(fig, path)


def fig_closest_approach(m: SwarmMetrics, path: Path) -> str:
    """Closest approach per step of pairs in visibility and of pairs not in visibility."""
    plt = _plt()
    a = m.approach
    th = m.t_s[:-1] / H
    fig, ax = plt.subplots(figsize=(8, 3.8))
    ax.semilogy(th, a["visible_distance_m"], lw=0.7, color="C0", label="pairs in visibility")
    ax.semilogy(th, a["hidden_distance_m"], lw=0.7, color="C3", label="pairs not in visibility")
    ax.axhline(D_MIN_TRANS_M, color="k", ls="--", lw=0.8, label=f"d_min_trans = {D_MIN_TRANS_M:g} m")
    ax.set_xlabel("time [h]")
    ax.set_ylabel("min pair distance [m]")
    ax.set_title("Closest approach of any pair in each step (Hermite-interpolated)")
    ax.legend(loc="upper right")
    return _save(fig, path)


# --- html -----------------------------------------------------------------------------------------------
_CSS = ("body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
        "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;font-size:13px}"
        "th{background:#eee}figure{margin:1.5em 0}figcaption{font-size:13px;color:#333}img{max-width:100%}"
        ".ok{color:#060}.bad{color:#a00}")


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}" if abs(v) < 1e4 else f"{v:.0f}"
    return html.escape(str(v))


def _page(title: str, head_rows: list[tuple[str, str]], figures: list[tuple[str, str]], extra: str = "") -> str:
    rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{v}</td></tr>" for k, v in head_rows)
    figs = "".join(f'<figure><img src="{html.escape(f)}" alt="{html.escape(f)}"><figcaption>{c}</figcaption></figure>'
                   for f, c in figures)
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1><table>{rows}</table>{extra}{figs}"
            "</body></html>")


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100.0 * x:.1f} %"


def _check(ok: bool) -> str:
    return '<span class="ok">yes</span>' if ok else '<span class="bad">no</span>'


def _headline(summary: dict[str, Any], met: dict[str, Any]) -> list[tuple[str, str]]:
    c, cv, ctl, ca = met["connectivity"], met["closest_visible_steady"], met["control"], met["closest_approach"]
    st = met["steady_from_s"] / H

    def mn(d: dict) -> str:
        return f"min {_fmt(d.get('min'))}, p05 {_fmt(d.get('p05'))}, median {_fmt(d.get('median'))}, " \
               f"{_fmt(100 * d.get('fraction_ge_threshold', float('nan')))} % >= {_fmt(d.get('threshold'))}"

    def ap(d: dict) -> str:
        return "none" if d["distance_m"] is None else f"{_fmt(d['distance_m'])} m ({'-'.join(d['pair'])} at {_fmt(d['t_s'] / H)} h)"

    return [
        ("run", _fmt(summary.get("run"))),
        ("scenario / controller", f"{_fmt(summary.get('scenario'))} / {_fmt(summary.get('controller'))}"),
        ("spacecraft, duration", f"{summary.get('agents', '?')} spacecraft, {_fmt(met['t_end_s'] / H)} h"),
        ("always weakly connected (every step)",
         f"{_check(c['always_weakly_connected'])} ({_pct(c['weakly_connected_fraction'])} of the steps; max "
         f"{c['max_components']} components, {c['components_end']} at the end (largest {c['largest_component_end']}); "
         f"first split {'never' if c['first_split_t_s'] is None else _fmt(c['first_split_t_s'] / H) + ' h'})"),
        ("weakly connected over each orbit (union of the last orbit's digraphs)",
         f"{_pct(c.get('orbit_union_weakly_connected_fraction'))} of the steps after the first orbit; "
         f"max {c.get('orbit_union_max_components')} components"),
        (f"along-track to closest visible, t >= {st:.1f} h [m]", mn(cv["along_track_m"])),
        ("  orbit-minimum a(|dl|-2|de|) [m]", mn(cv["along_track_orbit_min_m"])),
        ("  radial a|de| [m]", mn(cv["radial_m"])),
        ("  cross-track a|di| [m]", mn(cv["cross_track_m"])),
        ("  parallelism", mn(cv["parallelism"])),
        ("parallelism, all visible pairs, steady", mn(met["visible_pairs_parallelism_steady"])),
        ("total dV [m/s]", f"{_fmt(ctl['delta_v_total_mps'], 4)} (max per spacecraft {_fmt(ctl['delta_v_max_spacecraft_mps'])}; "
                           f"{_fmt(ctl['delta_v_in_steady_window_mps'])} in the steady window, "
                           f"{_fmt(ctl['delta_v_last_hour_mps'])} in the last hour; 95 % spent by "
                           f"{_fmt(ctl['t_95pct_delta_v_s'] / H)} h)"),
        ("max |a| [m/s^2]", _fmt(ctl["accel_max_mps2"])),
        ("closest approach, all pairs", ap(ca["all_pairs"])),
        ("closest approach, pairs in visibility", ap(ca["visible_pairs"])),
        ("closest approach, pairs not in visibility", ap(ca["non_visible_pairs"])),
        ("closest approach in steady window: visible / not visible",
         f"{ap(ca['visible_pairs_steady'])} / {ap(ca['non_visible_pairs_steady'])}"),
    ]


def _camera_for(run_dir: Path, summary: dict[str, Any]) -> CameraGeometry:
    """The camera of a run: from earlier metrics, the configuration the recording carries
    (dashboards/run_config.py), and for recordings older than that the sweep's scenario_doc.json,
    the scenario file of the same name in deploy/scenarios, or else the paper's (500 m, 1080 px,
    f = 1000 px)."""
    cam = summary.get("metrics", {}).get("camera")
    if cam:
        return CameraGeometry(cam["detection_range_m"], int(cam["image_px"]), cam["focal_px"])
    recorded = camera_from_config(run_config(run_dir))
    if recorded is not None:
        return recorded
    doc_path = run_dir / "scenario_doc.json"
    if doc_path.is_file():
        c = json.loads(doc_path.read_text()).get("camera", {})
        return CameraGeometry(c.get("detection_range_m", 500.0), int(c.get("image_px", 1080)), c.get("focal_px", 1000.0))
    src = summary.get("scenario_file")
    path = Path(__file__).resolve().parent.parent / "deploy" / "scenarios" / str(src)
    if src and path.is_file():
        from deploy.scenario import ScenarioError, load_scenario

        try:
            c = load_scenario(path).camera
            return CameraGeometry(c["detection_range_m"], c["image_px"], c["focal_px"])
        except ScenarioError:
            pass
    return CameraGeometry()


def write_report(run_dir: str | Path, *, cam: CameraGeometry | None = None, steady_from_s: float | None = None,
                 projection_last_s: float | None = 3 * 5677.0, figures: bool = True) -> Path:
    """Metrics into run_dir/summary.json["metrics"] and their time series into
    run_dir/metrics_series.npz; with `figures`, the PNGs and run_dir/report/index.html."""
    run_dir = Path(run_dir)
    spath = run_dir / "summary.json"
    summary = json.loads(spath.read_text()) if spath.is_file() else {}
    cam = cam or _camera_for(run_dir, summary)
    truth = read_truth(run_dir / "run.mcap", summary.get("run"))
    m = compute_metrics(truth, cam, steady_from_s)
    met = m.summary
    met["camera"] = {"detection_range_m": cam.detection_range_m, "image_px": cam.image_px, "focal_px": cam.focal_px}
    summary["metrics"] = met
    spath.write_text(json.dumps(summary, indent=1))
    np.savez_compressed(run_dir / SERIES, t_s=m.t_s, n_components=m.n_components, largest=m.largest,
                        n_components_orbit=m.n_components_orbit,
                        delta_v_total_mps=m.delta_v_mps.sum(axis=1))
    if not figures:
        return spath
    out = run_dir / "report"
    out.mkdir(exist_ok=True)
    summary.setdefault("config", run_config(run_dir) or {})
    figs = _paper002_figures(truth, m, met, out, projection_last_s) if _is_paper002(summary) else []
    sections = _mission_sections(run_dir, out, summary, truth)
    if sections:
        spath.write_text(json.dumps(summary, indent=1))
    title = f"swarmhil report: {summary.get('scenario', truth.run)}"
    page = _page(title, _headline(summary, met), figs,
                 "<p>Metrics computed from the recorded truth (dashboards/metrics.py); the full numbers are in "
                 "<code>summary.json</code> under <code>metrics</code>.</p>" + sections)
    (out / "index.html").write_text(page)
    return out / "index.html"


def _paper002_figures(truth: TruthArrays, m: SwarmMetrics, met: dict[str, Any], out: Path,
                      projection_last_s: float | None) -> list[tuple[str, str]]:
    """The figures of paper 002 (Figs. 7-22), for runs of its controllers only."""
    ids = truth.ids
    controlled = met["control"]["delta_v_total_mps"] > 0
    last = len(truth.t_s) - 1
    return [
        (fig_components(m, len(ids), out / "components.png"),
         "Weakly connected components of the visibility digraph and size of the largest (paper Figs. 10, 31)."),
        (fig_digraph(truth, m, 0, out / "digraph_start.png", "start"), "Visibility digraph at the start (paper Figs. 8-9)."),
        (fig_digraph(truth, m, last, out / "digraph_end.png", "end"), "Visibility digraph at the end (paper Fig. 11)."),
        (fig_roe_com(truth, (0, 1), out / "roe_a_l.png", "12"), "a da and a dl relative to the centre of mass (paper Fig. 12)."),
        (fig_roe_com(truth, (2, 3), out / "roe_e.png", "13"), "a dex, a dey relative to the centre of mass (paper Fig. 13)."),
        (fig_roe_com(truth, (4, 5), out / "roe_i.png", "14"), "a dix, a diy relative to the centre of mass (paper Fig. 14)."),
        (fig_separation(m, "along_track_m", D_MIN_M, "|y_k - y_j| [m]",
                        "Along-track distance to the closest visible neighbour (paper Fig. 15)", out / "sep_along.png",
                        extra="along_min_m"),
         f"Instantaneous along-track separation from each spacecraft to its closest visible neighbour; red: d_min = "
         f"{D_MIN_M:g} m; dotted: the smallest orbit-minimum a(|dl|-2|de|) of section 3.3. Grey: steady window."),
        (fig_separation(m, "cross_m", D_MIN_TRANS_M, "a|di_jk| [m]",
                        "Out-of-plane size of the relative ellipse, closest visible neighbour (paper Fig. 16)",
                        out / "sep_cross.png"), f"Red: d_min_trans = {D_MIN_TRANS_M:g} m."),
        (fig_separation(m, "radial_m", D_MIN_TRANS_M, "a|de_jk| [m]",
                        "Radial size of the relative ellipse, closest visible neighbour (paper Fig. 17)",
                        out / "sep_radial.png"), f"Red: d_min_trans = {D_MIN_TRANS_M:g} m."),
        (fig_parallelism(m, out / "parallelism.png"), "Parallelism |de.di|/(|de||di|) (paper Fig. 18); red: 0.8."),
        (fig_accel(m, ids, out / "accel.png"), "Commanded acceleration after the actuator limit (paper Fig. 19)."),
        (fig_dv(m, ids, out / "dv.png"), "Cumulative dV (paper Fig. 20); grey: steady window."),
        (fig_along_track(truth, out / "along_track.png",
                         "Along-track position relative to the centre of mass (paper Fig. 21)" if controlled
                         else "Along-track position of the uncontrolled swarm (paper Fig. 7)"),
         "Along-track position relative to the swarm centre of mass."),
        (fig_projections(truth, out / "projections.png", projection_last_s),
         "Cross-track and in-orbit projections of the trajectories relative to the centre of mass (paper Fig. 22)."),
        (fig_closest_approach(m, out / "closest_approach.png"),
         "Minimum distance over each step of pairs in visibility (either direction) and of pairs not in "
         "visibility: the paper's safety claim covers visible pairs only."),
    ]


PAPER002_CONTROLLERS = {"null", "drift-null", "sabatini"}


def _is_paper002(summary: dict[str, Any]) -> bool:
    from dashboards.sections import controllers_of

    cfg = summary.get("config") or {}
    return not cfg or controllers_of(cfg) <= PAPER002_CONTROLLERS


def _mission_sections(run_dir: Path, out: Path, summary: dict[str, Any], truth: TruthArrays) -> str:
    """Run every registered report section that applies to this run (dashboards/sections/): metrics
    into summary["metrics"][name], figures under their own heading. Returns the HTML."""
    from dashboards.sections import SectionContext, sections_for

    cfg = summary["config"]  # write_report filled it from the recording
    blocks = []
    for name, fn in sections_for(cfg):
        res = fn(SectionContext(run_dir, run_dir / "run.mcap", out, summary, cfg, truth))
        summary["metrics"][name] = res.metrics
        figs = "".join(f'<figure><img src="{html.escape(f)}" alt="{html.escape(f)}"><figcaption>{c}</figcaption>'
                       f'</figure>' for f, c in res.figures)
        blocks.append(f"<h2>{html.escape(res.title)}</h2>{res.html}{figs}")
    return "".join(blocks)


# --- sweep -------------------------------------------------------------------------------------------------
def write_sweep_report(sweep_dir: str | Path, param: str, cases: Sequence[dict[str, Any]]) -> Path:
    """Figs. 30-31 for a sweep. `cases`: dicts with value, seed, dir (a run dir whose summary.json
    already holds "metrics"), and optionally error. Writes sweep_dir/report/index.html and sweep.json."""
    plt = _plt()
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for c in cases:
        row = {"value": c["value"], "seed": c.get("seed"), "dir": str(c["dir"]), "error": c.get("error")}
        s = Path(c["dir"]) / "summary.json"
        if not c.get("error") and s.is_file():
            met = json.loads(s.read_text()).get("metrics", {})
            if met:
                row.update({
                    "delta_v_total_mps": met["control"]["delta_v_total_mps"],
                    "delta_v_last_hour_mps": met["control"]["delta_v_last_hour_mps"],
                    "weakly_connected_fraction": met["connectivity"]["weakly_connected_fraction"],
                    "orbit_union_weakly_connected_fraction":
                        met["connectivity"].get("orbit_union_weakly_connected_fraction"),
                    "always_weakly_connected": met["connectivity"]["always_weakly_connected"],
                    "max_components": met["connectivity"]["max_components"],
                    "components_end": met["connectivity"]["components_end"],
                    "first_split_t_s": met["connectivity"]["first_split_t_s"],
                    "closest_visible_pairs_m": met["closest_approach"]["visible_pairs"]["distance_m"],
                    "closest_non_visible_pairs_m": met["closest_approach"]["non_visible_pairs"]["distance_m"],
                    "along_track_min_steady_m": met["closest_visible_steady"]["along_track_m"].get("min"),
                })
        rows.append(row)
    (sweep_dir / "sweep.json").write_text(json.dumps({"param": param, "cases": rows}, indent=1))
    good = [r for r in rows if "delta_v_total_mps" in r]
    figs = []
    if good:
        xs = np.array([float(r["value"]) if _is_number(r["value"]) else i for i, r in enumerate(good)])
        fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        ax[0].plot(xs, [r["delta_v_total_mps"] for r in good], "o", color="C0")
        for x in np.unique(xs):
            v = [r["delta_v_total_mps"] for r, xx in zip(good, xs) if xx == x]
            ax[0].plot([x], [np.mean(v)], "_", ms=20, color="k")
        ax[0].set_ylabel("total dV [m/s]")
        ax[0].set_ylim(bottom=0.0)
        ax[0].set_title(f"Total dV against {param} (paper 002 Fig. 30)")
        ax[1].plot(xs, [r["weakly_connected_fraction"] for r in good], "o", color="C1", label="fraction of steps weakly connected")
        ax[1].plot(xs, [r.get("orbit_union_weakly_connected_fraction") or np.nan for r in good], "s", mfc="none",
                   color="C2", label="fraction weakly connected over the last orbit (union)")
        ax[1].plot(xs, [1.0 / r["max_components"] for r in good], "x", color="C3", label="1 / max components")
        ax[1].set_ylim(-0.05, 1.05)
        ax[1].set_xlabel(param)
        ax[1].legend(loc="lower left")
        ax[1].set_title("Swarm integrity")
        figs.append((_save(fig, out / "sweep_dv_connectivity.png"), "Total dV and connectivity per case (paper Fig. 30)."))
        fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
        for i, r in enumerate(good):
            ser = np.load(Path(r["dir"]) / SERIES)
            lab = f"{param}={r['value']}" + (f" seed {r['seed']}" if r.get("seed") is not None else "")
            ax[0].step(ser["t_s"] / H, ser["n_components"], where="post", lw=0.9, label=lab, color=f"C{i % 10}")
            if "n_components_orbit" in ser:
                ax[1].step(ser["t_s"] / H, ser["n_components_orbit"], where="post", lw=0.9, color=f"C{i % 10}")
            ax[2].plot(ser["t_s"] / H, ser["delta_v_total_mps"], lw=0.9, label=lab, color=f"C{i % 10}")
        ax[0].set_ylabel("weakly connected\ncomponents")
        ax[0].set_title("Connectedness per case (paper Fig. 31)")
        ax[0].legend(fontsize=6, ncol=2)
        ax[1].set_ylabel("components of the\nunion over the last orbit")
        ax[2].set_ylabel("total dV [m/s]")
        ax[2].set_xlabel("time [h]")
        figs.append((_save(fig, out / "sweep_components_dv_time.png"), "Components and total dV over time, per case."))
    head = [("parameter", html.escape(param)), ("cases", str(len(rows)))]
    cols = ["value", "seed", "delta_v_total_mps", "delta_v_last_hour_mps", "weakly_connected_fraction",
            "orbit_union_weakly_connected_fraction", "max_components",
            "components_end", "first_split_t_s", "along_track_min_steady_m", "closest_visible_pairs_m",
            "closest_non_visible_pairs_m", "error"]
    table = "<table><tr>" + "".join(f"<th>{c}</th>" for c in cols + ["report"]) + "</tr>"
    for r in rows:
        case_page = Path(r["dir"]) / "report" / "index.html"
        try:
            href = "../" + case_page.resolve().relative_to(sweep_dir.resolve()).as_posix()
            link = f'<a href="{html.escape(href)}">report</a>' if case_page.is_file() else "metrics only"
        except ValueError:
            link = html.escape(str(case_page))
        table += "<tr>" + "".join(f"<td>{_fmt(r.get(c))}</td>" for c in cols) + f"<td>{link}</td></tr>"
    table += "</table>"
    (out / "index.html").write_text(_page(f"swarmhil sweep: {param}", head, figs, table))
    return out / "index.html"


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)
