"""dashboards/metrics.py against hand-built configurations and brute-force references."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.dashboards.metrics import (
    closest_approach, closest_approach_series, closest_visible, delta_v_from_accel, ellipse_dims, parallelism,
    relative_to_com, visibility_series, visible_pair_parallelism, weak_components,
)
from swarmhil.plant.dynamics.roe_linear import mean_motion, roe_to_lvlh
from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

CAM = CameraGeometry()  # paper 002: 500 m, square FOV tan = 0.54, boresight +y
A_M = 6878137.0
N_RADPS = mean_motion(A_M)


def chain(n: int, spacing_m: float) -> np.ndarray:
    """(1, n, 3) spacecraft on the along-track axis, spacing_m apart."""
    pos = np.zeros((1, n, 3))
    pos[0, :, 1] = np.arange(n) * spacing_m
    return pos


def test_chain_200m_is_weakly_connected_and_a_600m_gap_splits_it():
    pos = chain(5, 200.0)
    vis = visibility_series(pos, CAM)
    # each spacecraft sees the ones ahead within 500 m: j -> j+1, j -> j+2
    assert vis[0, 0, 1] and vis[0, 0, 2] and not vis[0, 0, 3] and not vis[0, 1, 0]
    n, labels = weak_components(vis)
    assert n[0] == 1
    pos[0, 4, 1] = pos[0, 3, 1] + 600.0  # the leader moves 600 m ahead: out of range of everyone
    n, labels = weak_components(visibility_series(pos, CAM))
    assert n[0] == 2
    assert len(set(labels[0, :4])) == 1 and labels[0, 4] != labels[0, 0]
    pos = chain(6, 200.0)
    pos[0, 3:, 1] += 600.0  # 0-1-2 | 3-4-5 with an 800 m gap
    pos[0, 5, 1] += 600.0  # and 5 alone, 800 m ahead of 4
    n, labels = weak_components(visibility_series(pos, CAM))
    assert n[0] == 3
    assert labels[0, 0] == labels[0, 2] and labels[0, 3] == labels[0, 4] != labels[0, 0] != labels[0, 5]


def test_field_of_view_and_direction():
    pos = np.zeros((1, 3, 3))
    pos[0, 1] = (0.53 * 300.0, 300.0, 0.0)  # inside the square FOV (|x/y| <= 0.54)
    pos[0, 2] = (0.0, 300.0, 0.56 * 300.0)  # outside in cross-track
    vis = visibility_series(pos, CAM)[0]
    assert vis[0, 1] and not vis[0, 2] and not vis[1, 0]
    n, _ = weak_components(vis[None])
    assert n[0] == 2  # spacecraft 2 is isolated


@pytest.mark.parametrize("de,di,expected", [
    ((1.0, 0.0), (2.0, 0.0), 1.0),
    ((1.0, 0.0), (0.0, 3.0), 0.0),
    ((1.0, 1.0), (1.0, 0.0), 1.0 / np.sqrt(2.0)),
    ((1.0, 2.0), (-1.0, -2.0), 1.0),  # antiparallel counts as parallel (absolute value)
    ((0.0, 0.0), (1.0, 0.0), 0.0),
    ((np.cos(0.3), np.sin(0.3)), (np.cos(1.1), np.sin(1.1)), np.cos(0.8)),
])
def test_parallelism_of_known_vectors(de, di, expected):
    assert parallelism(np.array(de), np.array(di)) == pytest.approx(expected, abs=1e-12)


def test_ellipse_dims_match_the_relative_orbit_over_one_revolution():
    """Radial and cross-track sizes a|de|, a|di| are the amplitudes of x(u), z(u) of a drift-free pair;
    a(|dl| - 2|de|) is the smallest along-track separation over the orbit (section 3.3)."""
    pair = np.array([0.0, 180.0, 25.0, -20.0, 10.0, 35.0])
    u = np.linspace(0.0, 2 * np.pi, 20001)[:, None]
    pos = roe_to_lvlh(np.broadcast_to(pair, (u.size, 6)), u[:, 0], N_RADPS)[0]
    d = ellipse_dims(pair)
    assert d["radial_m"] == pytest.approx((pos[:, 0].max() - pos[:, 0].min()) / 2, rel=1e-6)
    assert d["cross_m"] == pytest.approx((pos[:, 2].max() - pos[:, 2].min()) / 2, rel=1e-6)
    assert d["along_min_m"] == pytest.approx(np.abs(pos[:, 1]).min(), rel=1e-6)
    assert d["along_mean_m"] == pytest.approx(180.0)


def test_closest_visible_picks_the_nearest_seen_neighbour():
    roe = np.zeros((1, 4, 6))
    roe[0, :, 1] = [0.0, 300.0, 150.0, -400.0]  # sc1 300 m ahead of sc0, sc2 150 m ahead, sc3 behind
    roe[0, 2, 2:4] = (40.0, 0.0)
    roe[0, 2, 4:6] = (0.0, 20.0)
    pos, _ = roe_to_lvlh(roe[0], 0.0, N_RADPS)
    pos = pos[None]
    vis = visibility_series(pos, CAM)
    cv = closest_visible(pos, roe, vis)
    assert cv.index[0, 0] == 2  # sees 1 and 2, picks 2
    assert cv.along_track_m[0, 0] == pytest.approx(abs(pos[0, 2, 1] - pos[0, 0, 1]))
    assert cv.radial_m[0, 0] == pytest.approx(40.0) and cv.cross_m[0, 0] == pytest.approx(20.0)
    assert cv.parallelism[0, 0] == pytest.approx(0.0)
    assert cv.index[0, 1] == -1 and np.isnan(cv.range_m[0, 1])  # the leader sees nobody
    pp = visible_pair_parallelism(roe, vis)
    assert np.isnan(pp[0, 1, 0]) and pp[0, 0, 2] == pytest.approx(0.0)


def _propagate(roe0: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keplerian drift of free ROE (dl += -3/2 n da t) mapped to LVLH: (T, N, 3) each."""
    roe = np.repeat(roe0[None], t_s.size, axis=0)
    roe[:, :, 1] += -1.5 * N_RADPS * roe0[None, :, 0] * t_s[:, None]
    return roe_to_lvlh(roe, (N_RADPS * t_s)[:, None], N_RADPS)


def test_closest_approach_matches_brute_force_between_samples():
    rng = np.random.default_rng(4)
    roe0 = rng.normal(0.0, 1.0, (5, 6)) * [30.0, 0.0, 20.0, 20.0, 20.0, 20.0]
    roe0[:, 1] = [0.0, 250.0, -250.0, 500.0, 900.0]
    roe0[1, 0] = 60.0  # drifts through the others: close passes that fall between samples
    t = np.arange(0.0, 4 * 3600.0 + 1e-9, 10.0)
    pos, vel = _propagate(roe0, t)
    vis = visibility_series(pos, CAM)
    series = closest_approach_series(pos, vel, t, vis, substeps=8)
    fine_t = np.arange(0.0, t[-1] + 1e-9, 0.1)
    fpos, _ = _propagate(roe0, fine_t)
    jj, kk = np.triu_indices(5, 1)
    d = np.linalg.norm(fpos[:, jj] - fpos[:, kk], axis=2)  # (F, P)
    best = np.unravel_index(np.argmin(d), d.shape)
    got = closest_approach(series, 5, "all")
    assert got.distance_m == pytest.approx(d[best], abs=2e-3)  # metres
    assert got.t_s == pytest.approx(fine_t[best[0]], abs=0.5)
    assert {got.pair[0], got.pair[1]} == {int(jj[best[1]]), int(kk[best[1]])}
    sampled = np.linalg.norm(pos[:, jj] - pos[:, kk], axis=2).min()
    assert got.distance_m <= sampled + 1e-9
    # per class: brute force with the class of each fine sample taken at the start of its interval
    interval = np.minimum((fine_t // 10.0).astype(int), len(t) - 2)
    seen = vis[interval][:, jj, kk] | vis[interval][:, kk, jj]
    for cls, mask in (("visible", seen), ("hidden", ~seen)):
        ref = np.where(mask, d, np.inf).min()
        assert closest_approach(series, 5, cls).distance_m == pytest.approx(ref, abs=2e-3)


def test_relative_to_com_and_delta_v_accounting():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(7, 4, 6))
    alive = np.ones((7, 4), dtype=bool)
    rel = relative_to_com(x, alive)
    assert np.allclose(rel.sum(axis=1), 0.0)
    alive[:, 3] = False
    rel = relative_to_com(x, alive)
    assert np.allclose(rel[:, :3].sum(axis=1), 0.0)
    acc = np.zeros((4, 2, 3))
    acc[0, 0] = (3e-4, 4e-4, 0.0)  # |a| = 5e-4 over 10 s
    acc[2, 1] = (0.0, 0.0, -1e-3)
    dv = delta_v_from_accel(acc, np.array([0.0, 10.0, 20.0, 30.0]))
    assert dv[-1] == pytest.approx([5e-3, 1e-2])
    assert dv[1, 0] == pytest.approx(5e-3) and dv[2, 1] == 0.0


def test_closest_approach_finds_a_fast_pass_between_samples():
    """A 1 m/s flyby with 0.3 m miss distance between two 10 s samples (constant acceleration:
    the cubic Hermite is exact); the samples alone would say metres."""
    t = np.arange(0.0, 101.0, 10.0)
    tc = 43.7  # time of closest approach

    def state(tt):
        rel = np.stack([0.3 + 0.5 * 1e-4 * (tt - tc) ** 2, 1.0 * (tt - tc), np.zeros_like(tt)], axis=-1)
        vrel = np.stack([1e-4 * (tt - tc), np.ones_like(tt), np.zeros_like(tt)], axis=-1)
        pos = np.zeros((tt.size, 2, 3))
        vel = np.zeros((tt.size, 2, 3))
        pos[:, 0], vel[:, 0] = rel, vrel
        return pos, vel

    pos, vel = state(t)
    series = closest_approach_series(pos, vel, t, None, substeps=8)
    fine = np.linspace(0.0, 100.0, 200001)
    ref = np.linalg.norm(state(fine)[0][:, 0], axis=1)
    got = closest_approach(series, 2, "all")
    assert np.linalg.norm(pos[:, 0], axis=1).min() > 3.0
    assert got.distance_m == pytest.approx(ref.min(), abs=0.005)
    assert got.t_s == pytest.approx(fine[np.argmin(ref)], abs=0.05)


def test_window_union_keeps_links_seen_within_the_window():
    from swarmhil.dashboards.metrics import window_union

    t = np.arange(0.0, 100.0, 10.0)
    vis = np.zeros((t.size, 3, 3), dtype=bool)
    vis[:, 0, 1] = True
    vis[[2, 7], 1, 2] = True  # 1 sees 2 only at t = 20 s and 70 s
    union = window_union(vis, t, 30.0)  # window (t - 30, t]: the current step and the two before
    brute = np.array([vis[(t > tk - 30.0) & (t <= tk)].any(axis=0) for tk in t])
    assert np.array_equal(union, brute)
    n, _ = weak_components(union)
    assert list(n) == [2, 2, 1, 1, 1, 2, 2, 1, 1, 1]


def test_weak_components_equal_scipy_per_step():
    """Issue 16: the all-steps-at-once numpy version gives scipy's counts and labels, step by step."""
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(3)
    for _ in range(60):
        T, N = int(rng.integers(1, 30)), int(rng.integers(1, 22))
        vis = rng.random((T, N, N)) < rng.uniform(0.0, 0.3)
        n, labels = weak_components(vis)
        for t in range(T):
            n0, l0 = connected_components(vis[t], directed=True, connection="weak")
            assert n[t] == n0 and np.array_equal(labels[t], l0)


def _series_equal(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].tobytes() == b[k].tobytes(), k


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_pruned_closest_approach_equals_every_pair_evaluated():
    """Issue 16: the series with the pairs that cannot be an interval's minimum left out is the one
    of evaluating every pair, value for value (random swarms with fast close passes, ties of
    coincident pairs, NaN and dead spacecraft, and the relative orbits of a ROE swarm)."""
    from swarmhil.dashboards.metrics import closest_approach_series, closest_approach_series_all

    rng = np.random.default_rng(16)
    for case in range(60):
        T, N = int(rng.integers(2, 40)), int(rng.integers(2, 12))
        pos = rng.normal(scale=float(rng.choice([5.0, 100.0, 400.0])), size=(T, N, 3))
        vel = rng.normal(scale=float(rng.choice([0.01, 1.0, 30.0])), size=(T, N, 3))
        if case % 3 == 0:  # straight-line fly-bys: positions consistent with the velocities
            t = np.arange(T) * 10.0
            p0, v = rng.normal(scale=200.0, size=(N, 3)), rng.normal(scale=5.0, size=(N, 3))
            pos, vel = p0[None] + t[:, None, None] * v[None], np.broadcast_to(v, (T, N, 3)).copy()
        if case % 4 == 1 and N > 3:
            pos[:, 3] = pos[:, 2]  # a coincident pair: ties at zero distance
            vel[:, 3] = vel[:, 2]
        if case % 7 == 2:
            pos[rng.integers(T), rng.integers(N), 0] = np.nan
        t_s = np.cumsum(rng.uniform(1.0, 20.0, T))
        vis = rng.random((T, N, N)) < 0.2 if case % 2 else None
        for sub in (4, 8):
            _series_equal(closest_approach_series(pos, vel, t_s, vis, sub),
                          closest_approach_series_all(pos, vel, t_s, vis, sub))
    # a ROE swarm over three orbits, with its visibility
    n_radps = mean_motion(6878137.0)
    roe = rng.normal(scale=150.0, size=(20, 6))
    u = np.arange(1500) * 10.0 * n_radps
    pos, vel = (np.stack(x) for x in zip(*[roe_to_lvlh(roe, ui, n_radps) for ui in u]))
    vis = np.stack([visibility_matrix(p, CameraGeometry()) for p in pos])
    _series_equal(closest_approach_series(pos, vel, u / n_radps, vis),
                  closest_approach_series_all(pos, vel, u / n_radps, vis))


def test_series_over_many_steps_equal_the_per_step_functions():
    """visibility_series (many steps per numpy call) and visible_pair_parallelism (visible pairs
    only), issue 16: equal to plant/sensors.visibility_matrix step by step and to the parallelism
    of every pair, on a ROE swarm with dead spacecraft."""
    from swarmhil.dashboards.metrics import visible_pair_parallelism

    rng = np.random.default_rng(7)
    n_radps = mean_motion(6878137.0)
    roe = rng.normal(scale=200.0, size=(20, 6))
    u = np.arange(700) * 10.0 * n_radps
    pos = np.stack([roe_to_lvlh(roe, ui, n_radps)[0] for ui in u])
    alive = rng.random((700, 20)) < 0.9
    cam = CameraGeometry()
    vis = visibility_series(pos, cam, alive)
    assert np.array_equal(vis, np.stack([visibility_matrix(p, cam, a) for p, a in zip(pos, alive)])) and vis.sum() > 1000
    roe_t = np.broadcast_to(roe, (700, 20, 6)) + rng.normal(scale=5.0, size=(700, 20, 6))
    pair = roe_t[:, :, None, :] - roe_t[:, None, :, :]
    want = np.where(vis, parallelism(pair[..., 2:4], pair[..., 4:6]), np.nan)
    assert visible_pair_parallelism(roe_t, vis).tobytes() == want.tobytes()
