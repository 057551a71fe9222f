"""Navigation error against truth, from the recording alone (issue 4), and a comparison of runs.

What an agent believed is in its telemetry (MCAP topic `sc/<id>/tm`, `swarm/<run>/sc/<id>/tm` in
recordings made before the MCAP contract; DESIGN.md): each
`TrackEstimate` holds the estimated state of a neighbour k relative to the observer j (k minus j):
LVLH position and velocity and ROE in metres, a*(da, dl, dex, dey, dix, diy), with the 6x6 ROE
covariance where the estimator has one (agent/nav/base.py). What was true is the `Truth` of the
same step (the scene stimulus of step k is imaged from the truth of step k; dashboards/truth_io.py).

- Association: each track row is paired with the spacecraft k != j whose true relative position
  r_k - r_j is nearest to the track's estimated relative position (Euclidean, metres). The
  distance to the second nearest is kept: a row whose two candidates are about as near is
  ambiguous. A track whose associated spacecraft changes during its life has an identity switch.
- Errors: position e_r = r_hat - (r_k - r_j), velocity likewise, ROE e = roe_hat - (roe_k - roe_j);
  NEES = e^T P^-1 e (6 degrees of freedom; mean 6 for a consistent filter, Bar-Shalom et al.,
  "Estimation with Applications to Tracking and Navigation", sec. 5.4).
- What the controller acted on: the behaviour decisions in the same telemetry name the neighbour
  (a track id, or with ideal `rel` sensing the true id) and carry the ROE of the observer relative
  to the neighbour it used, roe_jk = -(roe_k - roe_j) (NOTES-002); its error against truth is the
  "decision ROE error". With ideal sensing it is zero.
- Coverage: the fraction of truly visible pairs (plant rule, plant/sensors.visibility_matrix) that
  have a track associated with them at that step.

`write_nav_report(run_dir)` writes run_dir/navreport/{index.html, nav_summary.json, nav_table.md,
*.png}; `write_comparison(run_dirs, out_dir)` the table across runs (total dV, weak connectivity,
separations, closest approach, navigation error) as Markdown, JSON and HTML.
"""
from __future__ import annotations

import html
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from dashboards.kit import figures_of, render
from dashboards.run_config import run_camera
from dashboards.run_metrics import summary_with_metrics
from dashboards.truth_io import TruthArrays, read_truth, run_id_of
from plant.sensors import visibility_series, weak_components

H = 3600.0
TELEMETRY_SCHEMA = "swarmhil.v1.Telemetry"
CHI2_6_95 = 12.592  # chi-square, 6 degrees of freedom, 95 % quantile
ROE_COMPONENTS = ["a da", "a dl", "a dex", "a dey", "a dix", "a diy"]


# --- reading -----------------------------------------------------------------------------------------
@dataclass
class TrackRows:
    """Every track of every agent at every step, one row each (R rows)."""

    step: np.ndarray  # (R,) int
    observer: np.ndarray  # (R,) index into the truth ids
    track: np.ndarray  # (R,) int code of (observer, track id), unique over the run
    track_names: list[str]  # code -> "<observer>/<track id>"
    position_m: np.ndarray  # (R, 3) estimated r_k - r_j, LVLH
    velocity_mps: np.ndarray  # (R, 3)
    roe_m: np.ndarray  # (R, 6) estimated roe_k - roe_j
    covariance_m2: np.ndarray  # (R, 6, 6), NaN where the estimator has none
    age_steps: np.ndarray  # (R,)
    used: np.ndarray  # (R,) bool: the controller made a decision on this track at this step

    @property
    def n(self) -> int:
        return int(self.step.shape[0])


@dataclass
class DecisionRows:
    """Every behaviour decision (one per neighbour the controller used at a step)."""

    step: np.ndarray  # (D,)
    observer: np.ndarray  # (D,)
    neighbour: list[str]  # track id or, with `rel` sensing, the spacecraft id
    roe_jk_m: np.ndarray  # (D, 6) ROE of the observer relative to the neighbour, as the controller used it


def _tm_topics(reader, run: str, ids: list[str]) -> dict[str, int]:
    summary = reader.get_summary()
    topics = {ch.topic for ch in summary.channels.values()} if summary is not None else set()
    want = {f"sc/{sid}/tm": j for j, sid in enumerate(ids)}
    want.update({f"swarm/{run}/sc/{sid}/tm": j for j, sid in enumerate(ids)})  # old recordings
    return {t: j for t, j in want.items() if t in topics}


def read_tracks(mcap_path: str | Path, run: str, ids: list[str]) -> tuple[TrackRows, DecisionRows]:
    """Tracks and decisions from every agent's Telemetry (decoded from the file's own schema)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    step, obs, code, pos, vel, roe, cov, age, used = [], [], [], [], [], [], [], [], []
    d_step, d_obs, d_nb, d_roe = [], [], [], []
    names: dict[tuple[int, str], int] = {}
    nan_cov = np.full(36, np.nan)
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topics = _tm_topics(reader, run, ids)
        if not topics:
            return _empty_tracks(), DecisionRows(np.zeros(0, int), np.zeros(0, int), [], np.zeros((0, 6)))
        for schema, ch, _msg, tm in reader.iter_decoded_messages(topics=list(topics)):
            if schema is None or schema.name != TELEMETRY_SCHEMA:
                continue
            j, k = topics[ch.topic], int(tm.header.step)
            decided = set()
            for d in tm.decisions:
                decided.add(d.neighbour)
                if len(d.roe_rel_m) == 6:
                    d_step.append(k)
                    d_obs.append(j)
                    d_nb.append(d.neighbour)
                    d_roe.append(list(d.roe_rel_m))
            for tr in tm.tracks:
                if len(tr.roe_m) != 6:
                    continue
                c = names.setdefault((j, tr.track), len(names))
                step.append(k)
                obs.append(j)
                code.append(c)
                pos.append((tr.position_m.x, tr.position_m.y, tr.position_m.z))
                vel.append((tr.velocity_mps.x, tr.velocity_mps.y, tr.velocity_mps.z))
                roe.append(list(tr.roe_m))
                cov.append(list(tr.covariance_m2) if len(tr.covariance_m2) == 36 else nan_cov)
                age.append(tr.age_steps)
                used.append(tr.track in decided)
    track_names = [""] * len(names)
    for (j, tid), c in names.items():
        track_names[c] = f"{ids[j]}/{tid}"
    rows = TrackRows(
        step=np.asarray(step, dtype=np.int64), observer=np.asarray(obs, dtype=np.int64),
        track=np.asarray(code, dtype=np.int64), track_names=track_names,
        position_m=np.asarray(pos, float).reshape(-1, 3), velocity_mps=np.asarray(vel, float).reshape(-1, 3),
        roe_m=np.asarray(roe, float).reshape(-1, 6), covariance_m2=np.asarray(cov, float).reshape(-1, 6, 6),
        age_steps=np.asarray(age, dtype=np.int64), used=np.asarray(used, dtype=bool))
    dec = DecisionRows(np.asarray(d_step, dtype=np.int64), np.asarray(d_obs, dtype=np.int64), d_nb,
                       np.asarray(d_roe, float).reshape(-1, 6))
    return rows, dec


def _empty_tracks() -> TrackRows:
    z = np.zeros(0, dtype=np.int64)
    return TrackRows(z, z, z, [], np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 6)), np.zeros((0, 6, 6)), z,
                     np.zeros(0, dtype=bool))


# --- association and errors ------------------------------------------------------------------------
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


# --- summary ------------------------------------------------------------------------------------------
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
    s: dict[str, Any] = {"definitions": "dashboards/navreport.py docstring", "track_rows": rows.n,
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


# --- figures -------------------------------------------------------------------------------------------
from dashboards.figstyle import pyplot as _plt  # noqa: E402
from dashboards.figstyle import save as _save  # noqa: E402
from dashboards.figstyle import time_unit  # noqa: E402


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


# --- one run ---------------------------------------------------------------------------------------------
def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, float):
        if not math.isfinite(v):
            return "n/a" if math.isnan(v) else str(v)
        return f"{v:.{digits}g}" if abs(v) < 1e5 else f"{v:.0f}"
    return str(v)


def _mp(block: dict[str, Any], key: str, scale: float = 1.0) -> str:
    b = block.get(key, {})
    if not b.get("count"):
        return "n/a"
    return f"{_fmt(b['median'] * scale)} / {_fmt(b['p95'] * scale)}"


def nav_table_rows(s: dict[str, Any]) -> list[tuple[str, str]]:
    """(quantity, value) rows of a run's navigation summary (median / 95 %)."""
    if not s.get("track_rows"):
        d = s.get("decision_roe_error", {})
        return [("tracks", "none (sensing without a camera pipeline)"),
                ("decision ROE error a.da / a.de / a.di [m] (median / 95 %)",
                 " ; ".join(_mp(d, k) for k in ("da_m", "de_m", "di_m")))]
    out = [("track rows / tracks / median life [steps]",
            f"{s['track_rows']} / {s['tracks']} / {_fmt(s['track_life_steps']['median'])}"),
           ("identity switches (tracks with one)", f"{s['identity_switches']} ({_fmt(100 * s['tracks_with_switch_fraction'])} %)"),
           ("ambiguous association (second candidate < 2x nearest)", f"{_fmt(100 * (s['ambiguous_association_fraction'] or 0))} %"),
           ("coverage of truly visible pairs", f"{_fmt(100 * s.get('coverage_of_visible_pairs', float('nan')))} %"),
           ("rows used by the controller", f"{_fmt(100 * s['used_fraction'])} %")]
    if "coverage_of_visible_pairs_used" in s:
        out += [("visible pairs with a track the controller used", f"{_fmt(100 * s['coverage_of_visible_pairs_used'])} %"),
                ("used rows whose neighbour was not visible", f"{_fmt(100 * (s['used_rows_not_visible_fraction'] or 0))} %"),
                ("weakly connected per step: graph of used tracks / visibility graph",
                 f"{_fmt(100 * s['used_graph_weakly_connected_fraction'])} % / "
                 f"{_fmt(100 * s['visibility_weakly_connected_fraction'])} %")]
    if "held_back_fraction" in s:
        p = lambda v: "-" if v is None else f"{_fmt(100 * v)} %"  # noqa: E731
        b = s["held_back_fraction_by_range"]
        out += [("visible pairs with a track the controller did not use: run / first "
                 f"{_fmt(s['held_back_start_s'] / H)} h / after",
                 f"{p(s['held_back_fraction'])} / {p(s['held_back_fraction_start'])} / {p(s['held_back_fraction_after_start'])}"),
                ("... by true range / detection range 0-0.6 / 0.6-0.9 / 0.9-1",
                 f"{p(b['0-0.6'])} / {p(b['0.6-0.9'])} / {p(b['0.9-1'])}")]
    for label, key in (("all tracks", "all_tracks"), ("used by the controller", "tracks_used_by_controller")):
        b = s[key]
        out += [(f"{label}: position error [m] (median / 95 %)", _mp(b, "position_m")),
                (f"{label}: velocity error [mm/s]", _mp(b, "velocity_mps", 1e3)),
                (f"{label}: a.da / a.dl error [m]", f"{_mp(b, 'roe_da_m')} ; {_mp(b, 'roe_dl_m')}"),
                (f"{label}: a.de / a.di error (norms) [m]", f"{_mp(b, 'roe_de_m')} ; {_mp(b, 'roe_di_m')}"),
                (f"{label}: NEES mean / median / fraction <= chi2(95 %)",
                 "n/a" if not b["nees"].get("count") else
                 f"{_fmt(b['nees']['mean'])} / {_fmt(b['nees']['median'])} / {_fmt(b['nees']['fraction_below_chi2_95'])}")]
    return out


@dataclass
class RunNav:
    truth: TruthArrays
    rows: TrackRows
    err: NavErrors
    decisions: DecisionRows
    decision_err: np.ndarray
    summary: dict[str, Any]


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
    vis = visibility_series(truth.position_m, cam, truth.alive) if rows.n else None
    s = nav_summary(rows, err, derr, vis)
    if vis is not None:
        s.update(held_back_summary(rows, err, vis, truth, cam.detection_range_m))
    s["run"] = truth.run
    return RunNav(truth, rows, err, dec, derr, s)


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


def write_nav_report(run_dir: str | Path) -> Path:
    """Navigation error of a run against truth: run_dir/navreport/index.html (+ PNGs, nav_summary.json,
    nav_table.md). Returns the path of index.html."""
    run_dir = Path(run_dir)
    nav = analyse_run(run_dir)
    out = run_dir / "navreport"
    out.mkdir(exist_ok=True)
    (out / "nav_summary.json").write_text(json.dumps(nav.summary, indent=1))
    table = nav_table_rows(nav.summary)
    (out / "nav_table.md").write_text(_markdown(["quantity", "value"], [list(r) for r in table]))
    figs = nav_figures(nav, out)
    render("page.html", out / "index.html", title=f"Navigation error: {nav.truth.run}",
           head=[(k, html.escape(v)) for k, v in table],
           figures=figures_of(out, figs), intro="<p>Definitions: dashboards/navreport.py. Numbers: nav_summary.json.</p>")
    return out / "index.html"


# --- comparison of runs ------------------------------------------------------------------------------------
def comparison_row(run_dir: str | Path, label: str | None = None) -> dict[str, Any]:
    """One run's line of the comparison: swarm metrics from truth and its navigation error."""
    run_dir = Path(run_dir)
    nav_path = run_dir / "navreport" / "nav_summary.json"
    if not nav_path.is_file():
        write_nav_report(run_dir)
    nav = json.loads(nav_path.read_text())
    summary = summary_with_metrics(run_dir)
    met = summary["metrics"]
    c, cv, ca = met["connectivity"], met["closest_visible_steady"], met["closest_approach"]
    cw = met.get("closest_visible_whole_run", {})
    used = nav.get("tracks_used_by_controller", {})
    dec = nav.get("decision_roe_error", {})
    return {
        "label": label or summary.get("scenario") or run_dir.name, "run": summary.get("run"), "dir": str(run_dir),
        "duration_h": met["t_end_s"] / H,
        "delta_v_total_mps": met["control"]["delta_v_total_mps"],
        "delta_v_last_hour_mps": met["control"]["delta_v_last_hour_mps"],
        "delta_v_steady_mps": met["control"]["delta_v_in_steady_window_mps"],
        "weakly_connected_fraction": c["weakly_connected_fraction"],
        "orbit_union_weakly_connected_fraction": c.get("orbit_union_weakly_connected_fraction"),
        "max_components": c["max_components"],
        "along_track_min_m": cw.get("along_track_m", {}).get("min"),
        "along_track_p05_steady_m": cv["along_track_m"].get("p05"),
        "radial_p05_steady_m": cv["radial_m"].get("p05"),
        "cross_p05_steady_m": cv["cross_track_m"].get("p05"),
        "closest_approach_m": ca["all_pairs"]["distance_m"],
        "closest_approach_visible_m": ca["visible_pairs"]["distance_m"],
        "nav_position_median_m": used.get("position_m", {}).get("median"),
        "nav_position_p95_m": used.get("position_m", {}).get("p95"),
        "nav_da_median_m": dec.get("da_m", {}).get("median"),
        "nav_da_p95_m": dec.get("da_m", {}).get("p95"),
        "nav_de_median_m": dec.get("de_m", {}).get("median"),
        "nav_di_median_m": dec.get("di_m", {}).get("median"),
        "nees_mean": used.get("nees", {}).get("mean"),
        "coverage": nav.get("coverage_of_visible_pairs"),
    }


COLUMNS = [
    ("label", "run", None),
    ("delta_v_total_mps", "total dV [m/s]", 4),
    ("dv_ratio", "dV / first", 3),
    ("delta_v_steady_mps", "dV in the steady window (last sixth) [m/s]", 3),
    ("weakly_connected_fraction", "weakly connected (fraction of steps)", 4),
    ("orbit_union_weakly_connected_fraction", "weakly connected, union over an orbit", 4),
    ("along_track_min_m", "min along-track to closest visible [m]", 3),
    ("along_track_p05_steady_m", "along-track p05, steady [m]", 3),
    ("radial_p05_steady_m", "radial a.de p05, steady [m]", 3),
    ("cross_p05_steady_m", "cross-track a.di p05, steady [m]", 3),
    ("closest_approach_m", "closest approach [m]", 3),
    ("nav_position_median_m", "position error used, median / 95 % [m]", 3),
    ("nav_da_median_m", "a.da error used, median / 95 % [m]", 3),
    ("nav_de_median_m", "a.de / a.di error used, median [m]", 3),
    ("nees_mean", "NEES mean (6 = consistent)", 3),
    ("coverage", "visible pairs tracked", 3),
]


def _cell(row: dict[str, Any], key: str, digits: int | None) -> str:
    if key == "nav_position_median_m":
        return "-" if row[key] is None else f"{_num(row[key])} / {_num(row['nav_position_p95_m'])}"
    if key == "nav_da_median_m":
        return "-" if row[key] is None else f"{_num(row[key])} / {_num(row['nav_da_p95_m'])}"
    if key == "nav_de_median_m":
        return "-" if row[key] is None else f"{_num(row[key])} / {_num(row['nav_di_median_m'])}"
    v = row.get(key)
    if v is None:
        return "-"
    return _fmt(v, digits) if digits else str(v)


def _num(v: Any) -> str:
    """A number for the table; errors below a nanometre (ideal sensing, rounding only) print as 0."""
    return "-" if v is None else ("0" if abs(v) < 1e-9 else _fmt(v, 3))


def _markdown(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def write_comparison(run_dirs: Sequence[str | Path], out_dir: str | Path, labels: Sequence[str] | None = None) -> Path:
    """comparison.md / .json / .html in out_dir over the runs (the first is the dV reference)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [comparison_row(d, None if labels is None else labels[i]) for i, d in enumerate(run_dirs)]
    ref = rows[0]["delta_v_total_mps"] if rows else 0.0
    for r in rows:
        r["dv_ratio"] = r["delta_v_total_mps"] / ref if ref else None
    header = [h for _, h, _ in COLUMNS]
    cells = [[_cell(r, k, d) for k, _, d in COLUMNS] for r in rows]
    md = _markdown(header, cells)
    (out / "comparison.md").write_text(md)
    (out / "comparison.json").write_text(json.dumps(rows, indent=1))
    th = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    tb = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in cells)
    render("page.html", out / "comparison.html", title="Runs compared",
           intro=f"<table><tr>{th}</tr>{tb}</table><p>Swarm metrics from truth (dashboards/metrics.py), navigation "
                 "error from telemetry against truth (dashboards/navreport.py). Separations: closest visible "
                 "neighbour; p05 over the steady window (last sixth of the run).</p>")
    return out / "comparison.md"

