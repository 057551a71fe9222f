"""Swarm metrics of paper 002 (sections 4.1-4.2, 5; Figs. 10-22, 30-31) computed from TRUTH arrays.

Everything here is a pure function over numpy arrays shaped (T steps, N spacecraft, ...), as read
by dashboards/truth_io.py; nothing uses what the agents believed. Definitions:

- Visibility digraph (section 4.1): edge j -> k when j's camera sees k: k within the detection
  range and inside j's square field of view around +y (the plant's rule, plant/sensors.py).
  Integrity = one weakly connected component (numbered as scipy.sparse.csgraph.connected_components does), at
  every step; also reported for the union of the digraphs over the last orbital period (a link
  that the relative ellipse takes beyond 500 m for part of each orbit still counts there).
- Pair ROE: dalpha_jk = roe_j - roe_k (metres; the linear ROE of j relative to k, NOTES-002).
  Its relative ellipse (Figs. 15-17): along-track separation |y_k - y_j| (instantaneous; the mean
  a|dl| and the orbit minimum a(|dl| - 2|de|) of section 3.3 are kept too), radial dimension
  a|de| and out-of-plane (cross-track) dimension a|di|.
- Parallelism (Algorithm 1, Fig. 18): |de . di| / (|de| |di|) of visible pairs, 0 if either is 0.
- Control: |a| of the command applied over each step, cumulative dV per spacecraft (Figs. 19-20).
- Closest approach: minimum distance of any pair at any time, with a cubic Hermite interpolation
  of the relative position between samples (positions and velocities at both ends); reported for
  all pairs, for pairs in visibility (j sees k or k sees j at the start of the interval) and for
  pairs not in visibility, which the paper's safety claim does not cover.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmhil.missions.p002_sabatini.contract import D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN  # the thresholds of its section 3.2, Algorithm 1
from swarmhil.plant.sensors import CameraGeometry, visibility_series, weak_components


# --- graph --------------------------------------------------------------------------------------
def window_union(vis: np.ndarray, t_s: np.ndarray, window_s: float) -> np.ndarray:
    """(T, N, N) bool: j saw k at some step of (t - window_s, t]; e.g. one orbital period, so that a
    link lost over part of every relative orbit still counts."""
    c = np.concatenate([np.zeros((1,) + vis.shape[1:], dtype=np.int64), np.cumsum(vis, axis=0, dtype=np.int64)])
    first = np.searchsorted(t_s, t_s - window_s, side="right")  # first step inside the window
    return (c[1:] - c[first]) > 0


def largest_component(labels: np.ndarray) -> np.ndarray:
    """(T,) size of the largest weakly connected component."""
    return np.array([np.bincount(row).max() for row in labels])


# --- pair geometry --------------------------------------------------------------------------------
def parallelism(de: np.ndarray, di: np.ndarray) -> np.ndarray:
    """|de . di| / (|de| |di|) over the last axis (length 2); 0 where either vector vanishes."""
    den = np.linalg.norm(de, axis=-1) * np.linalg.norm(di, axis=-1)
    dot = np.abs(np.sum(de * di, axis=-1))
    ok = den > 1e-12
    return np.where(ok, dot / np.where(ok, den, 1.0), 0.0)


def ellipse_dims(roe_pair_m: np.ndarray) -> dict[str, np.ndarray]:
    """Relative-ellipse sizes of pair ROE a*dalpha (..., 6): mean along-track a|dl|, orbit-minimum
    along-track a(|dl| - 2|de|) (section 3.3), radial a|de|, cross-track a|di|, parallelism."""
    de, di = roe_pair_m[..., 2:4], roe_pair_m[..., 4:6]
    de_m, di_m = np.linalg.norm(de, axis=-1), np.linalg.norm(di, axis=-1)
    dl_m = np.abs(roe_pair_m[..., 1])
    return {"along_mean_m": dl_m, "along_min_m": dl_m - 2.0 * de_m, "radial_m": de_m, "cross_m": di_m,
            "parallelism": parallelism(de, di)}


@dataclass(frozen=True)
class ClosestVisible:
    """For each step and spacecraft j, the closest (by range) spacecraft k that j sees; NaN if none."""

    index: np.ndarray  # (T, N) k, -1 when j sees nobody
    range_m: np.ndarray  # (T, N)
    along_track_m: np.ndarray  # (T, N) |y_k - y_j| now
    along_mean_m: np.ndarray  # (T, N) a|dl_jk|
    along_min_m: np.ndarray  # (T, N) a(|dl_jk| - 2|de_jk|)
    radial_m: np.ndarray  # (T, N) a|de_jk|
    cross_m: np.ndarray  # (T, N) a|di_jk|
    parallelism: np.ndarray  # (T, N)


def pair_ranges(position_m: np.ndarray) -> np.ndarray:
    """(T, N, N) |r_k - r_j|."""
    d = position_m[:, None, :, :] - position_m[:, :, None, :]
    return np.sqrt(np.einsum("tjki,tjki->tjk", d, d))


def closest_visible(position_m: np.ndarray, roe_m: np.ndarray, vis: np.ndarray) -> ClosestVisible:
    T, N, _ = position_m.shape
    rng = np.where(vis, pair_ranges(position_m), np.inf)
    k = np.argmin(rng, axis=2)
    has = np.isfinite(np.take_along_axis(rng, k[..., None], axis=2)[..., 0])
    tt, jj = np.meshgrid(np.arange(T), np.arange(N), indexing="ij")
    pair = roe_m[tt, jj] - roe_m[tt, k]
    dims = ellipse_dims(pair)
    nan = lambda a: np.where(has, a, np.nan)  # noqa: E731
    return ClosestVisible(
        index=np.where(has, k, -1),
        range_m=nan(rng[tt, jj, k]),
        along_track_m=nan(np.abs(position_m[tt, k, 1] - position_m[tt, jj, 1])),
        along_mean_m=nan(dims["along_mean_m"]), along_min_m=nan(dims["along_min_m"]),
        radial_m=nan(dims["radial_m"]), cross_m=nan(dims["cross_m"]), parallelism=nan(dims["parallelism"]),
    )


def visible_pair_parallelism(roe_m: np.ndarray, vis: np.ndarray) -> np.ndarray:
    """(T, N, N) parallelism of dalpha_jk where j sees k, NaN elsewhere (computed for the visible
    pairs only: `parallelism` is elementwise, so the values are those of every pair's)."""
    out = np.full(vis.shape, np.nan)
    t, j, k = np.nonzero(vis)
    for a in range(0, len(t), 1 << 18):
        sl = slice(a, a + (1 << 18))
        pair = roe_m[t[sl], j[sl]] - roe_m[t[sl], k[sl]]
        out[t[sl], j[sl], k[sl]] = parallelism(pair[..., 2:4], pair[..., 4:6])
    return out


# --- frames ----------------------------------------------------------------------------------------
def relative_to_com(x: np.ndarray, alive: np.ndarray | None = None) -> np.ndarray:
    """x (T, N, d) minus the swarm centre of mass (equal masses, alive spacecraft) at each step."""
    w = np.ones(x.shape[:2]) if alive is None else alive.astype(float)
    w = np.where(w.sum(axis=1, keepdims=True) > 0, w, 1.0)
    com = np.einsum("tn,tnd->td", w, x) / w.sum(axis=1)[:, None]
    return x - com[:, None, :]


# --- control ---------------------------------------------------------------------------------------
def accel_norm(accel_mps2: np.ndarray) -> np.ndarray:
    """(T, N) |a| of the command held over each step."""
    return np.linalg.norm(accel_mps2, axis=-1)


def delta_v_from_accel(accel_mps2: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """(T, N) cumulative sum of |a| dt (the plant's dV accounting), 0 at the first sample."""
    dt = np.diff(t_s)
    inc = accel_norm(accel_mps2[:-1]) * dt[:, None]
    return np.vstack([np.zeros((1, accel_mps2.shape[1])), np.cumsum(inc, axis=0)])


# --- closest approach ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Approach:
    distance_m: float
    pair: tuple[int, int]
    t_s: float

    def as_dict(self, ids: list[str]) -> dict[str, Any]:
        if not np.isfinite(self.distance_m):
            return {"distance_m": None, "pair": None, "t_s": None}
        return {"distance_m": float(self.distance_m), "pair": [ids[self.pair[0]], ids[self.pair[1]]],
                "t_s": float(self.t_s)}


def _hermite_min(p0: np.ndarray, v0: np.ndarray, p1: np.ndarray, v1: np.ndarray, h: np.ndarray,
                 substeps: int) -> tuple[np.ndarray, np.ndarray]:
    """Min |p(s)| and its s over s in [0, 1] of the cubic Hermite p(s) through (p0, v0), (p1, v1);
    arrays (..., 3), h (...,) interval length. Sampled at substeps+1 points then refined by a
    parabola through the best sample's squared distance and its neighbours'."""
    s = np.linspace(0.0, 1.0, substeps + 1)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    hh = h[..., None, None]
    p = (h00[:, None] * p0[..., None, :] + h10[:, None] * hh * v0[..., None, :]
         + h01[:, None] * p1[..., None, :] + h11[:, None] * hh * v1[..., None, :])
    d2 = np.einsum("...i,...i->...", p, p)  # squared distance: smooth, quadratic near a close pass
    i = np.argmin(d2, axis=-1)
    dmin = np.take_along_axis(d2, i[..., None], -1)[..., 0]
    im, ip = np.clip(i - 1, 0, substeps), np.clip(i + 1, 0, substeps)
    dm = np.take_along_axis(d2, im[..., None], -1)[..., 0]
    dp = np.take_along_axis(d2, ip[..., None], -1)[..., 0]
    curv = dm - 2 * dmin + dp
    inner = (i > 0) & (i < substeps) & (curv > 0)
    off = np.where(inner, 0.5 * (dm - dp) / np.where(inner, curv, 1.0), 0.0)
    dref = np.where(inner, dmin - 0.25 * (dm - dp) * off, dmin)
    return np.sqrt(np.clip(np.minimum(dref, dmin), 0.0, None)), (i + off) / substeps


def closest_approach_series(position_m: np.ndarray, velocity_mps: np.ndarray, t_s: np.ndarray,
                            vis: np.ndarray | None = None, substeps: int = 8) -> dict[str, np.ndarray]:
    """Per interval [t_k, t_k+1): the minimum pair distance and its pair and time, for all pairs
    and, when `vis` is given, separately for pairs in visibility at t_k (either direction) and
    pairs not in visibility. Returns arrays of length T-1 (NaN / -1 where no pair of that class).

    The interpolated minimum (`_hermite_min`) is computed only for the pairs that can hold an
    interval's minimum of a class (issue 16: about 1 in 20 pairs): a pair is left out when a
    lower bound of its interpolated distance exceeds the smallest endpoint distance of the class
    in that interval. The bound: on [0, 1] the Hermite weights give h00 + h01 = 1 (both in
    [0, 1]) and |h10|, |h11| <= 4/27, so |p(s)| >= m = (|p0| + |p1| - |p1 - p0|) / 2 - 4/27 h
    (|v0| + |v1|) and |p(s)| <= M = max(|p0|, |p1|) + 4/27 h (|v0| + |v1|); the sampled minimum of
    the squared distance is >= m^2, and the parabolic refinement lowers it by at most a quarter of
    the spread of the samples, so the result is >= sqrt(1.25 m^2 - 0.25 M^2) (with a margin for
    rounding). A pair left out therefore never is the minimum nor ties it: the series is the one
    of evaluating every pair (`closest_approach_series_all`), value for value
    (tests/test_metrics.py)."""
    return _closest_approach_series(position_m, velocity_mps, t_s, vis, substeps, prune=True)


def closest_approach_series_all(position_m: np.ndarray, velocity_mps: np.ndarray, t_s: np.ndarray,
                                vis: np.ndarray | None = None, substeps: int = 8) -> dict[str, np.ndarray]:
    """`closest_approach_series` with every pair evaluated (the reference its pruning is tested against)."""
    return _closest_approach_series(position_m, velocity_mps, t_s, vis, substeps, prune=False)


_BOUND_REL = 1e-9  # relative rounding margin of the pruning bounds (double rounding errors are ~1e-15)


def _closest_approach_series(position_m: np.ndarray, velocity_mps: np.ndarray, t_s: np.ndarray,
                             vis: np.ndarray | None, substeps: int, prune: bool) -> dict[str, np.ndarray]:
    T, N, _ = position_m.shape
    jj, kk = np.triu_indices(N, 1)
    out = {f"{c}_{f}": np.full(T - 1, np.nan if f != "pair" else -1.0)
           for c in ("all", "visible", "hidden") for f in ("distance_m", "t_s", "pair")}
    if N < 2 or T < 2:
        return out
    for t0 in range(0, T - 1, 256):
        sl = slice(t0, min(t0 + 256, T - 1))
        sl1 = slice(sl.start + 1, sl.stop + 1)
        p0 = position_m[sl][:, jj] - position_m[sl][:, kk]
        v0 = velocity_mps[sl][:, jj] - velocity_mps[sl][:, kk]
        p1 = position_m[sl1][:, jj] - position_m[sl1][:, kk]
        v1 = velocity_mps[sl1][:, jj] - velocity_mps[sl1][:, kk]
        h = np.broadcast_to((t_s[sl1] - t_s[sl])[:, None], p0.shape[:2])
        classes = {"all": np.ones(p0.shape[:2], dtype=bool)}
        if vis is not None:
            seen = vis[sl][:, jj, kk] | vis[sl][:, kk, jj]
            classes.update(visible=seen, hidden=~seen)
        if prune:
            d = np.full(p0.shape[:2], np.inf)
            s = np.zeros(p0.shape[:2])
            ti, pi = np.nonzero(_candidates(p0, v0, p1, v1, h, classes))
            d[ti, pi], s[ti, pi] = _hermite_min(p0[ti, pi], v0[ti, pi], p1[ti, pi], v1[ti, pi], h[ti, pi], substeps)
        else:
            d, s = _hermite_min(p0, v0, p1, v1, h, substeps)  # (t, P)
        tmin = t_s[sl][:, None] + s * h
        for c, mask in classes.items():
            dm = np.where(mask, d, np.inf)
            best = np.argmin(dm, axis=1)
            val = np.take_along_axis(dm, best[:, None], 1)[:, 0]
            ok = np.isfinite(val)
            out[f"{c}_distance_m"][sl] = np.where(ok, val, np.nan)
            out[f"{c}_t_s"][sl] = np.where(ok, np.take_along_axis(tmin, best[:, None], 1)[:, 0], np.nan)
            out[f"{c}_pair"][sl] = np.where(ok, best, -1)
    return out


def _candidates(p0: np.ndarray, v0: np.ndarray, p1: np.ndarray, v1: np.ndarray, h: np.ndarray,
                classes: dict[str, np.ndarray]) -> np.ndarray:
    """(t, P) bool: the pairs whose interpolated distance can be their class's minimum of the
    interval (bounds in `closest_approach_series`); NaN anywhere makes a pair a candidate."""
    norm = lambda a: np.sqrt(np.einsum("...i,...i->...", a, a))  # noqa: E731
    r0, r1 = norm(p0), norm(p1)
    wobble = (4.0 / 27.0) * h * (norm(v0) + norm(v1))
    m = np.maximum(0.5 * (r0 + r1 - norm(p1 - p0)) - wobble, 0.0)
    big = np.maximum(r0, r1) + wobble
    lb2 = 1.25 * m * m - 0.25 * big * big - _BOUND_REL * big * big
    lb = np.sqrt(np.maximum(lb2, 0.0))
    ub = np.minimum(r0, r1) * (1.0 + _BOUND_REL)  # the interpolated minimum is at most an endpoint's distance
    cand = np.zeros(p0.shape[:2], dtype=bool)
    for mask in classes.values():
        thr = np.fmin.reduce(np.where(mask, ub, np.inf), axis=1)  # NaN-ignoring
        cand |= mask & ~(lb > thr[:, None])
    return cand


def closest_approach(series: dict[str, np.ndarray], n_bodies: int, cls: str = "all",
                     window: np.ndarray | None = None) -> Approach:
    """The overall minimum of one class of `closest_approach_series`, optionally within a mask of intervals."""
    d = series[f"{cls}_distance_m"]
    if window is not None:
        d = np.where(window, d, np.nan)
    if d.size == 0 or np.all(np.isnan(d)):
        return Approach(float("inf"), (-1, -1), float("nan"))
    i = int(np.nanargmin(d))
    jj, kk = np.triu_indices(n_bodies, 1)
    p = int(series[f"{cls}_pair"][i])
    return Approach(float(d[i]), (int(jj[p]), int(kk[p])), float(series[f"{cls}_t_s"][i]))


# --- everything, for summary.json --------------------------------------------------------------------
def _stats(x: np.ndarray, threshold: float | None = None) -> dict[str, Any]:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"count": 0}
    out = {"count": int(x.size), "min": float(x.min()), "p01": float(np.percentile(x, 1)),
           "p05": float(np.percentile(x, 5)), "median": float(np.median(x)), "max": float(x.max())}
    if threshold is not None:
        out["fraction_ge_threshold"] = float(np.mean(x >= threshold))
        out["threshold"] = threshold
    return out


@dataclass
class SwarmMetrics:
    """All per-step series of a run (for the report) and the scalar summary (for summary.json)."""

    t_s: np.ndarray
    vis: np.ndarray
    n_components: np.ndarray
    largest: np.ndarray
    n_components_orbit: np.ndarray  # components of the union of the digraphs over the last orbit
    closest: ClosestVisible
    pair_parallelism: np.ndarray
    accel_mps2: np.ndarray  # (T, N) norm
    delta_v_mps: np.ndarray  # (T, N)
    approach: dict[str, np.ndarray]
    steady: np.ndarray  # (T,) bool, steady-state window
    summary: dict[str, Any]


def compute_metrics(truth: Any, cam: CameraGeometry | None = None, steady_from_s: float | None = None,
                    substeps: int = 8) -> SwarmMetrics:
    """Metrics of a run from its TruthArrays. Steady state: t >= steady_from_s (default: the last
    sixth of the run, i.e. the last 4 h of 24 h; the paper's da has settled before 20 h)."""
    cam = cam or CameraGeometry()
    t = truth.t_s
    ids = truth.ids
    N = len(ids)
    if steady_from_s is None:
        steady_from_s = t[0] + (t[-1] - t[0]) * 5.0 / 6.0
    steady = t >= steady_from_s
    vis = visibility_series(truth.position_m, cam, truth.alive)
    ncomp, labels = weak_components(vis)
    largest = largest_component(labels)
    period_s = 2.0 * np.pi / truth.mean_motion_radps
    ncomp_orbit, _ = weak_components(window_union(vis, t, period_s))
    after_first_orbit = t >= t[0] + period_s
    cv = closest_visible(truth.position_m, truth.roe_m, vis)
    ppar = visible_pair_parallelism(truth.roe_m, vis)
    acc = accel_norm(truth.accel_mps2)
    dv = truth.delta_v_mps
    appr = closest_approach_series(truth.position_m, truth.velocity_mps, t, vis, substeps)
    steady_iv = steady[:-1]

    split = np.flatnonzero(ncomp > 1)
    dv_tot = dv.sum(axis=1)
    total = float(dv_tot[-1])
    i_steady = int(np.argmax(steady))
    last_hour = t >= t[-1] - 3600.0
    i_hour = int(np.argmax(last_hour))
    reached = lambda f: float(t[int(np.argmax(dv_tot >= f * total))]) if total > 0 else 0.0  # noqa: E731
    sees_nobody_end = [ids[j] for j in range(N) if not vis[-1, j].any()]
    seen_by_nobody_end = [ids[k] for k in range(N) if not vis[-1, :, k].any()]
    summary: dict[str, Any] = {
        "definitions": "dashboards/metrics.py docstring; steady state = t >= steady_from_s",
        "steps": int(t.size), "t_start_s": float(t[0]), "t_end_s": float(t[-1]), "steady_from_s": float(steady_from_s),
        "connectivity": {
            "weakly_connected_fraction": float(np.mean(ncomp == 1)),
            "weakly_connected_fraction_steady": float(np.mean(ncomp[steady] == 1)),
            "always_weakly_connected": bool(np.all(ncomp == 1)),
            "max_components": int(ncomp.max()), "components_start": int(ncomp[0]), "components_end": int(ncomp[-1]),
            "first_split_t_s": float(t[split[0]]) if split.size else None,
            "largest_component_min": int(largest.min()), "largest_component_end": int(largest[-1]),
            "orbit_period_s": float(period_s),
            "orbit_union_weakly_connected_fraction": float(np.mean(ncomp_orbit[after_first_orbit] == 1))
            if after_first_orbit.any() else None,
            "orbit_union_max_components": int(ncomp_orbit.max()),
            "edges_start": int(vis[0].sum()), "edges_end": int(vis[-1].sum()),
            "sees_nobody_end": sees_nobody_end, "seen_by_nobody_end": seen_by_nobody_end,
        },
        "closest_visible_steady": {
            "along_track_m": _stats(cv.along_track_m[steady], D_MIN_M),
            "along_track_mean_roe_m": _stats(cv.along_mean_m[steady], D_MIN_M),
            "along_track_orbit_min_m": _stats(cv.along_min_m[steady], D_MIN_M),
            "radial_m": _stats(cv.radial_m[steady], D_MIN_TRANS_M),
            "cross_track_m": _stats(cv.cross_m[steady], D_MIN_TRANS_M),
            "parallelism": _stats(cv.parallelism[steady], PARALLEL_MIN),
            "spacecraft_without_visible_neighbour_end": int(np.sum(cv.index[-1] < 0)),
        },
        "closest_visible_whole_run": {
            "along_track_m": _stats(cv.along_track_m, D_MIN_M),
            "radial_m": _stats(cv.radial_m, D_MIN_TRANS_M),
            "cross_track_m": _stats(cv.cross_m, D_MIN_TRANS_M),
        },
        "visible_pairs_parallelism_steady": _stats(ppar[steady], PARALLEL_MIN),
        "control": {
            "delta_v_total_mps": total,
            "delta_v_per_spacecraft_mps": {s: float(v) for s, v in zip(ids, dv[-1])},
            "delta_v_max_spacecraft_mps": float(dv[-1].max()),
            "delta_v_total_at_steady_start_mps": float(dv_tot[i_steady]),
            "delta_v_in_steady_window_mps": float(total - dv_tot[i_steady]),
            "delta_v_steady_fraction": float((total - dv_tot[i_steady]) / total) if total > 0 else 0.0,
            "delta_v_last_hour_mps": float(total - dv_tot[i_hour]),
            "t_95pct_delta_v_s": reached(0.95), "t_99pct_delta_v_s": reached(0.99),
            "accel_max_mps2": float(acc.max()),
            "accel_max_per_spacecraft_mps2": {s: float(v) for s, v in zip(ids, acc.max(axis=0))},
            "accel_nonzero_fraction_steady": float(np.mean(acc[steady] > 0)),
        },
        "closest_approach": {
            "all_pairs": closest_approach(appr, N, "all").as_dict(ids),
            "visible_pairs": closest_approach(appr, N, "visible").as_dict(ids),
            "non_visible_pairs": closest_approach(appr, N, "hidden").as_dict(ids),
            "all_pairs_steady": closest_approach(appr, N, "all", steady_iv).as_dict(ids),
            "visible_pairs_steady": closest_approach(appr, N, "visible", steady_iv).as_dict(ids),
            "non_visible_pairs_steady": closest_approach(appr, N, "hidden", steady_iv).as_dict(ids),
            "interpolation": f"cubic Hermite between samples, {substeps} sub-samples, parabolic refinement "
                             "of the squared distance",
        },
    }
    return SwarmMetrics(t_s=t, vis=vis, n_components=ncomp, largest=largest, n_components_orbit=ncomp_orbit,
                        closest=cv, pair_parallelism=ppar, accel_mps2=acc, delta_v_mps=dv, approach=appr,
                        steady=steady, summary=summary)
