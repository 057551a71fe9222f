"""Navigation error against truth: association of each track row with the nearest true neighbour, the
position, velocity and ROE errors, NEES, coverage of the visible pairs, and a run's summary (no files)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.navreport.read import DecisionRows, TrackRows, read_tracks
from swarmhil.dashboards.run_config import run_camera
from swarmhil.dashboards.truth_io import TruthArrays, read_truth, run_id_of
from swarmhil.plant.sensors import CameraGeometry, visibility_series, weak_components

H = 3600.0


CHI2_6_95 = 12.592  # chi-square, 6 degrees of freedom, 95 % quantile


@dataclass
class NavErrors:
    """Track rows associated with truth and their errors (R rows, as TrackRows)."""

    truth_row: np.ndarray  # (R,) row of the truth arrays (same step), -1 when the step is missing
    neighbour: np.ndarray  # (R,) associated spacecraft k (index into the truth ids)
    assoc_m: np.ndarray  # (R,) |r_hat - (r_k - r_j)|
    second_m: np.ndarray  # (R,) distance to the second-nearest candidate (inf with one candidate)
    range_m: np.ndarray  # (R,) true |r_k - r_j|
    position_err_m: np.ndarray  # (R, 3)
    velocity_err_mps: np.ndarray  # (R, 3)
    roe_err_m: np.ndarray  # (R, 6)
    nees: np.ndarray  # (R,) NaN without covariance
    switches: np.ndarray  # (R,) bool: the associated spacecraft differs from the track's previous row


def truth_rows_of_steps(truth: TruthArrays, steps: np.ndarray) -> np.ndarray:
    """Row of the truth arrays holding each step, -1 where the truth has no such step."""
    if truth.step.size == 0:
        return np.full(steps.shape, -1)
    i = np.clip(np.searchsorted(truth.step, steps), 0, truth.step.size - 1)
    return np.where(truth.step[i] == steps, i, -1)


def associate(rows: TrackRows, truth: TruthArrays, chunk: int = 50_000) -> NavErrors:
    """Nearest true neighbour of each track row (module docstring) and the errors against it."""
    R, N = rows.n, truth.n_bodies
    trow = truth_rows_of_steps(truth, rows.step)
    nb = np.full(R, -1, dtype=np.int64)
    d1 = np.full(R, np.nan)
    d2 = np.full(R, np.inf)
    for s in range(0, R, chunk):
        sl = slice(s, min(s + chunk, R))
        ok = trow[sl] >= 0
        tr, j = trow[sl][ok], rows.observer[sl][ok]
        rel = truth.position_m[tr] - truth.position_m[tr, j][:, None, :]  # (r, N, 3) r_k - r_j
        dist = np.linalg.norm(rel - rows.position_m[sl][ok][:, None, :], axis=2)
        dist[np.arange(dist.shape[0]), j] = np.inf  # not itself
        dist = np.where(np.isnan(dist), np.inf, dist)  # missing truth of a body
        order = np.argsort(dist, axis=1)[:, :2]
        idx = np.flatnonzero(ok) + s
        nb[idx] = order[:, 0]
        d1[idx] = np.take_along_axis(dist, order[:, :1], 1)[:, 0]
        if N > 2:
            d2[idx] = np.take_along_axis(dist, order[:, 1:2], 1)[:, 0]
    good = nb >= 0
    tr, j, k = trow[good], rows.observer[good], nb[good]
    pos_err = np.full((R, 3), np.nan)
    vel_err = np.full((R, 3), np.nan)
    roe_err = np.full((R, 6), np.nan)
    rng = np.full(R, np.nan)
    true_rel = truth.position_m[tr, k] - truth.position_m[tr, j]
    pos_err[good] = rows.position_m[good] - true_rel
    vel_err[good] = rows.velocity_mps[good] - (truth.velocity_mps[tr, k] - truth.velocity_mps[tr, j])
    roe_err[good] = rows.roe_m[good] - (truth.roe_m[tr, k] - truth.roe_m[tr, j])
    rng[good] = np.linalg.norm(true_rel, axis=1)
    nees = nees_of(roe_err, rows.covariance_m2)
    switches = np.zeros(R, dtype=bool)
    if R > 1:
        order = np.lexsort((rows.step, rows.track))
        same = rows.track[order][1:] == rows.track[order][:-1]
        changed = nb[order][1:] != nb[order][:-1]
        switches[order[1:]] = same & changed
    return NavErrors(trow, nb, d1, d2, rng, pos_err, vel_err, roe_err, nees, switches)


def nees_of(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """e^T P^-1 e per row; NaN where P is missing (NaN) or not positive definite."""
    out = np.full(err.shape[0], np.nan)
    ok = np.isfinite(cov).all(axis=(1, 2)) & np.isfinite(err).all(axis=1)
    if not ok.any():
        return out
    e, p = err[ok], 0.5 * (cov[ok] + cov[ok].transpose(0, 2, 1))
    try:
        chol = np.linalg.cholesky(p)
        y = np.linalg.solve(chol, e[..., None])[..., 0]
        out[ok] = np.einsum("ri,ri->r", y, y)
    except np.linalg.LinAlgError:  # some P not positive definite: row by row
        vals = np.full(e.shape[0], np.nan)
        for i in range(e.shape[0]):
            try:
                y = np.linalg.solve(np.linalg.cholesky(p[i]), e[i])
                vals[i] = y @ y
            except np.linalg.LinAlgError:
                pass
        out[ok] = vals
    return out


def decision_roe_errors(dec: DecisionRows, rows: TrackRows, err: NavErrors, truth: TruthArrays) -> np.ndarray:
    """(D, 6) error of the ROE each decision used: roe_jk_hat - (roe_j - roe_k). The neighbour is a
    spacecraft id (ideal sensing) or a track id, associated through the track row of the same
    step. NaN where neither resolves."""
    D = dec.step.shape[0]
    out = np.full((D, 6), np.nan)
    if D == 0:
        return out
    col = {sid: i for i, sid in enumerate(truth.ids)}
    by_track: dict[tuple[int, int, str], int] = {}
    names = rows.track_names
    for r in range(rows.n):
        by_track[(int(rows.step[r]), int(rows.observer[r]), names[rows.track[r]].split("/", 1)[1])] = r
    trow = truth_rows_of_steps(truth, dec.step)
    for i in range(D):
        if trow[i] < 0:
            continue
        j = int(dec.observer[i])
        k = col.get(dec.neighbour[i])
        if k is None:
            r = by_track.get((int(dec.step[i]), j, dec.neighbour[i]))
            if r is None or err.neighbour[r] < 0:
                continue
            k = int(err.neighbour[r])
        out[i] = dec.roe_jk_m[i] - (truth.roe_m[trow[i], j] - truth.roe_m[trow[i], k])
    return out


def track_graph(rows: TrackRows, err: NavErrors, shape: tuple[int, ...], used_only: bool = False) -> np.ndarray:
    """(T, N, N) bool: j has a track associated with k at that truth row (used_only: a track its
    controller acted on at that step)."""
    ok = (err.truth_row >= 0) & (rows.used if used_only else True)
    hit = np.zeros(shape, dtype=bool)
    hit[err.truth_row[ok], rows.observer[ok], err.neighbour[ok]] = True
    return hit


def coverage(rows: TrackRows, err: NavErrors, vis: np.ndarray, used_only: bool = False) -> float:
    """Fraction of (step, j, k) with j seeing k (truth) that have a track of j associated with k
    (used_only: a track the controller acted on; the rest were held back by [nav].control_max_sigma_m)."""
    total = int(vis.sum())
    if total == 0:
        return float("nan")
    return float((track_graph(rows, err, vis.shape, used_only) & vis).sum() / total)


def control_graph_summary(rows: TrackRows, err: NavErrors, vis: np.ndarray) -> dict[str, Any]:
    """What the controllers acted on against what the cameras saw (issue 16, camera connectivity):
    the share of used track rows whose neighbour was not visible at that step (a track kept through
    a few misses), and the per-step weak connectivity of the digraph j -> k of the tracks the
    controllers used, beside that of the plant's visibility digraph (dashboards/metrics.py)."""
    u = rows.used & (err.truth_row >= 0)
    seen = vis[err.truth_row[u], rows.observer[u], err.neighbour[u]]
    n_used, _ = weak_components(track_graph(rows, err, vis.shape, used_only=True))
    n_vis, _ = weak_components(vis)
    return {"used_rows_not_visible_fraction": float(np.mean(~seen)) if seen.size else None,
            "used_graph_weakly_connected_fraction": float(np.mean(n_used == 1)),
            "visibility_weakly_connected_fraction": float(np.mean(n_vis == 1))}


def held_back_summary(rows: TrackRows, err: NavErrors, vis: np.ndarray, truth: TruthArrays, max_range_m: float,
                      start_s: float = H) -> dict[str, Any]:
    """Visible pairs whose observer had a track the controller did not use (held back by
    [nav].control_max_sigma_m, or not confirmed yet), as a fraction of the visible pair-steps: over
    the run, in the first `start_s` and after it (the start-up transient), and by true range in
    bands of the detection range: [0, 0.6), [0.6, 0.9), [0.9, 1] (the far links decide connectivity)."""
    held = vis & track_graph(rows, err, vis.shape) & ~track_graph(rows, err, vis.shape, used_only=True)
    rel = truth.position_m[:, None, :, :] - truth.position_m[:, :, None, :]  # [t, j, k] = r_k - r_j
    frac = np.linalg.norm(rel, axis=3) / max_range_m
    early = (truth.t_s - truth.t_s[0] < start_s)[:, None, None]
    f = lambda m: float(np.sum(held & m) / np.sum(vis & m)) if np.any(vis & m) else None  # noqa: E731
    return {"held_back_fraction": f(np.ones_like(vis)), "held_back_start_s": float(start_s),
            "held_back_fraction_start": f(np.broadcast_to(early, vis.shape)),
            "held_back_fraction_after_start": f(np.broadcast_to(~early, vis.shape)),
            "held_back_fraction_by_range": {"0-0.6": f(frac < 0.6), "0.6-0.9": f((frac >= 0.6) & (frac < 0.9)),
                                            "0.9-1": f(frac >= 0.9)},
            "visible_pair_steps_by_range": {"0-0.6": int(np.sum(vis & (frac < 0.6))),
                                            "0.6-0.9": int(np.sum(vis & (frac >= 0.6) & (frac < 0.9))),
                                            "0.9-1": int(np.sum(vis & (frac >= 0.9)))}}


def _pct(x: np.ndarray) -> dict[str, Any]:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"count": 0}
    return {"count": int(x.size), "median": float(np.median(x)), "p95": float(np.percentile(x, 95)),
            "max": float(x.max()), "rms": float(np.sqrt(np.mean(x * x)))}


def roe_error_magnitudes(roe_err: np.ndarray) -> dict[str, np.ndarray]:
    """|a da|, |a dl|, |a de| (2-vector), |a di| (2-vector) errors."""
    return {"da_m": np.abs(roe_err[:, 0]), "dl_m": np.abs(roe_err[:, 1]),
            "de_m": np.hypot(roe_err[:, 2], roe_err[:, 3]), "di_m": np.hypot(roe_err[:, 4], roe_err[:, 5])}


def _error_block(pos_err: np.ndarray, vel_err: np.ndarray, roe_err: np.ndarray, nees: np.ndarray) -> dict[str, Any]:
    out: dict[str, Any] = {"position_m": _pct(np.linalg.norm(pos_err, axis=1)),
                           "velocity_mps": _pct(np.linalg.norm(vel_err, axis=1))}
    for name, v in roe_error_magnitudes(roe_err).items():
        out[f"roe_{name}"] = _pct(v)
    fin = nees[np.isfinite(nees)]
    out["nees"] = ({"count": int(fin.size), "mean": float(fin.mean()), "median": float(np.median(fin)),
                    "fraction_below_chi2_95": float(np.mean(fin <= CHI2_6_95)), "dof": 6}
                   if fin.size else {"count": 0})
    return out


def nav_summary(rows: TrackRows, err: NavErrors, dec_err: np.ndarray, vis: np.ndarray | None) -> dict[str, Any]:
    """Scalar navigation-error summary of a run (nav_summary.json)."""
    s: dict[str, Any] = {"definitions": "dashboards/navreport package docstring", "track_rows": rows.n,
                         "tracks": len(rows.track_names), "decision_rows": int(dec_err.shape[0])}
    ok = err.neighbour >= 0
    if rows.n:
        life = np.bincount(rows.track, minlength=len(rows.track_names))
        per_track_switch = np.bincount(rows.track, weights=err.switches.astype(float), minlength=len(life))
        s["track_life_steps"] = {"median": float(np.median(life)), "max": int(life.max())}
        s["identity_switches"] = int(err.switches.sum())
        s["tracks_with_switch_fraction"] = float(np.mean(per_track_switch > 0))
        ambiguous = ok & (err.second_m < 2.0 * err.assoc_m)
        s["ambiguous_association_fraction"] = float(np.mean(ambiguous[ok])) if ok.any() else None
        s["all_tracks"] = _error_block(err.position_err_m[ok], err.velocity_err_mps[ok], err.roe_err_m[ok], err.nees[ok])
        u = ok & rows.used
        s["tracks_used_by_controller"] = _error_block(err.position_err_m[u], err.velocity_err_mps[u],
                                                      err.roe_err_m[u], err.nees[u])
        s["used_fraction"] = float(np.mean(rows.used))
        if vis is not None:
            s["coverage_of_visible_pairs"] = coverage(rows, err, vis)
            s["coverage_of_visible_pairs_used"] = coverage(rows, err, vis, used_only=True)
            s.update(control_graph_summary(rows, err, vis))
    d_ok = np.isfinite(dec_err).all(axis=1)
    s["decision_roe_error"] = {k: _pct(v[d_ok]) for k, v in roe_error_magnitudes(dec_err).items()}
    s["decision_roe_error"]["resolved_fraction"] = float(d_ok.mean()) if d_ok.size else None
    return s


@dataclass
class RunNav:
    truth: TruthArrays
    rows: TrackRows
    err: NavErrors
    decisions: DecisionRows
    decision_err: np.ndarray
    summary: dict[str, Any]
    vis: np.ndarray | None = None  # (T, N, N) the plant's visibility digraph of each truth row (plant/sensors.py)
    camera: CameraGeometry | None = None  # the run's camera (range, square FOV) that visibility was computed with


def analyse_run(run_dir: str | Path) -> RunNav:
    """Read run_dir/run.mcap, associate, compute the errors and their summary (no files written)."""
    run_dir = Path(run_dir)
    spath = run_dir / "summary.json"
    summary = json.loads(spath.read_text()) if spath.is_file() else {}
    run = summary.get("run") or run_id_of(run_dir)
    truth = read_truth(run_dir / "run.mcap", run)
    rows, dec = read_tracks(run_dir / "run.mcap", truth.run, truth.ids)
    err = associate(rows, truth)
    derr = decision_roe_errors(dec, rows, err, truth)
    cam = run_camera(run_dir, summary)
    vis_all = visibility_series(truth.position_m, cam, truth.alive)
    vis = vis_all if rows.n else None
    s = nav_summary(rows, err, derr, vis)
    if vis is not None:
        s.update(held_back_summary(rows, err, vis, truth, cam.detection_range_m))
    s["run"] = truth.run
    return RunNav(truth, rows, err, dec, derr, s, vis_all, cam)

