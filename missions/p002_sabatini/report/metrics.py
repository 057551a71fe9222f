"""Paper 002's swarm metrics (Sabatini et al., sections 4.1-4.2, 5; Figs. 10-18, 30-31) from TRUTH
arrays: the metrics hook of its room (dashboards/metrics.py `register_mission_metrics`), run for
the runs its section covers (`applies`: flown only with its controllers, or recorded without a
configuration). Reading and analysis only: no figures, no pages. Definitions:

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
- Closest approach split by visibility (dashboards/metrics.py `closest_approach_series` with the
  digraph): pairs in visibility (j sees k or k sees j at the start of the interval) and pairs not
  in visibility, which the paper's safety claim does not cover.

Their numbers go where they always were, at the top of summary.json["metrics"] (`connectivity`,
`closest_visible_steady`, `closest_visible_whole_run`, `visible_pairs_parallelism_steady`, and
`closest_approach.visible_pairs` ...); the per-step components into the metrics_series table and
metrics_series.npz.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmhil.dashboards.metrics import (MetricsInput, MissionMetrics, accel_norm, closest_approach, closest_approach_series,
                                register_mission_metrics, stats)
from swarmhil.dashboards.sections import controllers_of
from swarmhil.missions.p002_sabatini.contract import CONTROLLER, D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN  # the thresholds of its section 3.2, Algorithm 1
from swarmhil.plant.sensors import visibility_series, weak_components

NAME = "p002-swarm"
PAPER002_CONTROLLERS = {"null", "drift-null", CONTROLLER}  # its law and the baselines of its Figs. 7-9


def applies(config: dict[str, Any]) -> bool:
    """Runs flown with paper 002's controllers only, and recordings without a configuration."""
    return not config or controllers_of(config) <= PAPER002_CONTROLLERS


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


# --- the hook -------------------------------------------------------------------------------------
@dataclass
class SwarmGraphMetrics:
    """Paper 002's per-step series of a run (its section's figures) beside the mission-neutral ones."""

    t_s: np.ndarray
    steady: np.ndarray  # (T,) bool
    vis: np.ndarray  # (T, N, N) j sees k
    n_components: np.ndarray
    largest: np.ndarray
    n_components_orbit: np.ndarray  # components of the union of the digraphs over the last orbit
    closest: ClosestVisible
    pair_parallelism: np.ndarray
    accel_mps2: np.ndarray  # (T, N) norm (the mission-neutral series, for Fig. 19)
    delta_v_mps: np.ndarray  # (T, N)
    approach: dict[str, np.ndarray]  # closest_approach_series with the visibility classes
    summary: dict[str, Any]  # paper 002's part of summary.json["metrics"] (and orbit_period_s for Fig. 10)


@register_mission_metrics(NAME, applies=applies)
def swarm_graph_metrics(given: MetricsInput) -> MissionMetrics:
    """Connectivity, separations from the closest visible neighbour, parallelism and the closest
    approach by visibility of one run (module docstring)."""
    truth, steady, t = given.truth, given.steady, given.truth.t_s
    ids = truth.ids
    N = len(ids)
    vis = visibility_series(truth.position_m, given.cam, truth.alive)
    ncomp, labels = weak_components(vis)
    largest = largest_component(labels)
    period_s = 2.0 * np.pi / truth.mean_motion_radps
    ncomp_orbit, _ = weak_components(window_union(vis, t, period_s))
    after_first_orbit = t >= t[0] + period_s
    cv = closest_visible(truth.position_m, truth.roe_m, vis)
    ppar = visible_pair_parallelism(truth.roe_m, vis)
    appr = closest_approach_series(truth.position_m, truth.velocity_mps, t, vis, given.substeps)
    steady_iv = steady[:-1]
    split = np.flatnonzero(ncomp > 1)
    summary: dict[str, Any] = {
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
            "sees_nobody_end": [ids[j] for j in range(N) if not vis[-1, j].any()],
            "seen_by_nobody_end": [ids[k] for k in range(N) if not vis[-1, :, k].any()],
        },
        "closest_visible_steady": {
            "along_track_m": stats(cv.along_track_m[steady], D_MIN_M),
            "along_track_mean_roe_m": stats(cv.along_mean_m[steady], D_MIN_M),
            "along_track_orbit_min_m": stats(cv.along_min_m[steady], D_MIN_M),
            "radial_m": stats(cv.radial_m[steady], D_MIN_TRANS_M),
            "cross_track_m": stats(cv.cross_m[steady], D_MIN_TRANS_M),
            "parallelism": stats(cv.parallelism[steady], PARALLEL_MIN),
            "spacecraft_without_visible_neighbour_end": int(np.sum(cv.index[-1] < 0)),
        },
        "closest_visible_whole_run": {
            "along_track_m": stats(cv.along_track_m, D_MIN_M),
            "radial_m": stats(cv.radial_m, D_MIN_TRANS_M),
            "cross_track_m": stats(cv.cross_m, D_MIN_TRANS_M),
        },
        "visible_pairs_parallelism_steady": stats(ppar[steady], PARALLEL_MIN),
        "closest_approach": {
            "visible_pairs": closest_approach(appr, N, "visible").as_dict(ids),
            "non_visible_pairs": closest_approach(appr, N, "hidden").as_dict(ids),
            "visible_pairs_steady": closest_approach(appr, N, "visible", steady_iv).as_dict(ids),
            "non_visible_pairs_steady": closest_approach(appr, N, "hidden", steady_iv).as_dict(ids),
        },
    }
    detail = SwarmGraphMetrics(t_s=t, steady=steady, vis=vis, n_components=ncomp, largest=largest,
                               n_components_orbit=ncomp_orbit, closest=cv, pair_parallelism=ppar,
                               accel_mps2=accel_norm(truth.accel_mps2), delta_v_mps=truth.delta_v_mps,
                               approach=appr, summary=summary)
    columns = {"n_components": ncomp.astype("int64"), "largest_component": largest.astype("int64"),
               "n_components_orbit_union": ncomp_orbit.astype("int64"),
               "visibility_edges": vis.sum(axis=(1, 2)).astype("int64")}
    arrays = {"n_components": ncomp, "largest": largest, "n_components_orbit": ncomp_orbit}
    return MissionMetrics(summary=summary, columns=columns, arrays=arrays, detail=detail)
