"""Paper 000's batch-path rewrites of issue 29 (capture-10's 550 s batch run ≤ 30 s) against the
code they replaced, byte for byte: the closest surface point (`_closest_point`, row by row instead
of Newton steps over arrays; `surface_frames`' stacked rotations), `dcm` and the plant's `cross`
without `np.stack`, the consensus of eq. 30 with its time-independent sums kept (`Consensus`), the
sensor's outlier directions (`landmark_returns`) and its noise generators (`keyed_rng`), and the
packets the batch link sends (`CommandBatch.transmissions`, without building each Command), and
the fits' residuals and Jacobian (`residuals_and_jacobian`: the prior's mean and block).

The references below are frozen copies of those functions at 4ef2732 (main before the change),
docstrings dropped; each test draws inputs that reach every branch (zero coordinates, the centre,
equal axes, points on and near the surface, transposed rotations, NaN), and compares bits."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarmhil.missions.p000_capture import contract as cc
from swarmhil.missions.p000_capture.contract import Ellipsoid
from swarmhil.missions.p000_capture.fsw import gnc_tls as gt
from swarmhil.missions.p000_capture.fsw.estimate import Consensus, TargetEstimate, consensus
from swarmhil.missions.p000_capture.sense import P000Params, landmark_returns, visible_landmarks
from swarmhil.plant.dynamics.frames import cross
from swarmhil.plant.sensing.registry import keyed_rng

ROOT = Path(__file__).resolve().parents[2]

# --- 4ef2732's code, the references ---------------------------------------------------------------


def ref_closest_point_principal(p: np.ndarray, a: np.ndarray, iters: int = 100) -> np.ndarray:
    pl = [float(v) for v in np.asarray(p, dtype=float).reshape(3)]
    al = [float(v) for v in np.asarray(a, dtype=float).reshape(3)]
    y = [abs(v) for v in pl]
    aa = [v * v for v in al]
    tiny = 1e-12 * max(al)
    cands: list[list[float]] = []

    # t = u − a_m² with a_m the smallest axis: a_k² + t = (a_k² − a_m²) + u keeps its digits near
    # the pole u → 0 (an interior point close to the plane of the smallest axis)
    m = aa.index(min(aa))
    ay0, ay1, ay2 = (al[k] * y[k] for k in range(3))
    d0, d1, d2 = (aa[k] - aa[m] for k in range(3))
    u = 1e-15 * max(1.0, aa[m])
    if (ay0 / (d0 + u)) ** 2 + (ay1 / (d1 + u)) ** 2 + (ay2 / (d2 + u)) ** 2 > 1.0:
        u = max(u, ay0 - d0, ay1 - d1, ay2 - d2)
        for _ in range(iters):  # python floats: a handful of steps
            r0, r1, r2 = ay0 / (d0 + u), ay1 / (d1 + u), ay2 / (d2 + u)
            s = r0 * r0 + r1 * r1 + r2 * r2
            if s <= 1.0:
                break
            slope = r0 * r0 / (d0 + u) + r1 * r1 / (d1 + u) + r2 * r2 / (d2 + u)  # −S′/2
            u_next = u + s * (math.sqrt(s) - 1.0) / slope  # Newton on S^-1/2 − 1
            if u_next <= u:
                break
            u = u_next
        cands.append([aa[0] * y[0] / (d0 + u), aa[1] * y[1] / (d1 + u), aa[2] * y[2] / (d2 + u)])
    for k in range(3):
        if y[k] > tiny:
            continue
        others = [j for j in range(3) if j != k]
        if any(abs(aa[j] - aa[k]) < 1e-15 for j in others):
            continue
        x = [0.0, 0.0, 0.0]
        for j in others:
            x[j] = aa[j] * y[j] / (aa[j] - aa[k])
        rest = 1.0 - sum((x[j] / al[j]) ** 2 for j in others)
        if rest >= 0.0:
            x[k] = al[k] * math.sqrt(rest)
            cands.append(x)
    if not cands:  # p at the centre of a sphere-like degenerate case: the smallest-axis tip
        x = [0.0, 0.0, 0.0]
        x[m] = al[m]
        cands.append(x)
    best = min(cands, key=lambda c: math.dist(c, y)) if len(cands) > 1 else cands[0]
    return np.array([-v if q < 0.0 else v for v, q in zip(best, pl)])


def ref_newton_principal(ay: np.ndarray, d: np.ndarray, u: np.ndarray, iters: int) -> np.ndarray:
    out = u.copy()
    rows = np.arange(len(u))
    ay0, ay1, ay2 = ay
    d0, d1, d2 = d
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(iters):
            if len(rows) == 0:
                break
            du0, du1, du2 = d0 + u, d1 + u, d2 + u
            r0, r1, r2 = ay0 / du0, ay1 / du1, ay2 / du2
            q0, q1, q2 = r0 * r0, r1 * r1, r2 * r2
            s = q0 + q1 + q2
            slope = q0 / du0 + q1 / du1 + q2 / du2
            u_next = u + s * (np.sqrt(s) - 1.0) / slope
            stops = (s <= 1.0) | (u_next <= u)  # (the scalar loop breaks on either)
            if not stops.any():
                u = u_next
                continue
            out[rows[stops]] = u[stops]
            moves = ~stops
            rows, u = rows[moves], u_next[moves]
            ay0, ay1, ay2, d0, d1, d2 = ay0[moves], ay1[moves], ay2[moves], d0[moves], d1[moves], d2[moves]
    out[rows] = u
    return out


def ref_closest_points_principal(p: np.ndarray, a: np.ndarray, iters: int = 100) -> np.ndarray:
    pts = np.asarray(p, dtype=float).reshape(-1, 3)
    al = np.asarray(a, dtype=float).reshape(-1, 3)
    y = np.abs(pts)
    aa = al * al
    m = np.argmin(aa, axis=1)  # (the first smallest, as list.index(min))
    aam = aa[np.arange(len(aa)), m]
    ay = al * y
    d = aa - aam[:, None]
    u = 1e-15 * np.where(aam > 1.0, aam, 1.0)
    start = [(a0 / (d0 + uu)) ** 2 + (a1 / (d1 + uu)) ** 2 + (a2 / (d2 + uu)) ** 2 > 1.0
             for (a0, a1, a2), (d0, d1, d2), uu in zip(ay.tolist(), d.tolist(), u.tolist())]
    general = np.array(start, dtype=bool) & (y > (1e-12 * al.max(axis=1))[:, None]).all(axis=1)
    out = np.empty_like(pts)
    for i in np.flatnonzero(~general).tolist():
        out[i] = ref_closest_point_principal(pts[i], al[i], iters)
    g = np.flatnonzero(general)
    if len(g) == 0:
        return out
    ay, d, u, aa, y = ay[g], d[g], u[g], aa[g], y[g]
    for k in range(3):  # u = max(u, ay_k − d_k), as Python's max keeps the first of equals
        v = ay[:, k] - d[:, k]
        u = np.where(v > u, v, u)
    u = ref_newton_principal(ay.T.copy(), d.T.copy(), u, iters)
    x = np.stack([aa[:, k] * y[:, k] / (d[:, k] + u) for k in range(3)], axis=1)
    out[g] = np.where(pts[g] < 0.0, -x, x)
    return out


def ref_surface_frames(ells: list[Ellipsoid], p_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts = np.asarray(p_m, dtype=float).reshape(-1, 3)
    if len(ells) != len(pts):
        raise ValueError(f"{len(ells)} ellipsoids for {len(pts)} points")
    local = np.array([e.rotation.T @ (q - e.centre_m) for e, q in zip(ells, pts)]).reshape(-1, 3)
    axes = np.array([e.semi_axes_m for e in ells], dtype=float).reshape(-1, 3)
    x = ref_closest_points_principal(local, axes)
    n = x / axes ** 2
    n = n / np.sqrt(cc.dot_rows(n, n))[:, None]
    gap = local - x
    dist = np.sqrt(cc.dot_rows(gap, gap))
    scaled = local / axes
    inside = cc.dot_rows(scaled, scaled) < 1.0
    x_s = np.array([e.centre_m + e.rotation @ xi for e, xi in zip(ells, x)]).reshape(-1, 3)
    normals = np.array([e.rotation @ ni for e, ni in zip(ells, n)]).reshape(-1, 3)
    return np.where(inside, -dist, dist), x_s, normals


def ref_dcm(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.moveaxis(np.asarray(q), -1, 0)
    rows = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def ref_consensus(own: TargetEstimate | None, others: list[TargetEstimate], t_s: float,
              own_weight: float) -> TargetEstimate | None:
    ests = ([own] if own is not None else []) + others
    if not ests:
        return None
    if own is not None and own.direct and others:
        w = np.array([own_weight] + [(1.0 - own_weight) / len(others)] * len(others))
    else:
        w = np.full(len(ests), 1.0 / len(ests))
    vel = np.array([e.velocity_mps for e in ests])
    ages = t_s - np.array([e.t_s for e in ests])
    # sums over the estimates, in their order (a reduction over axis 0 adds row after row)
    c = (w[:, None] * (np.array([e.centre_m for e in ests]) + vel * ages[:, None])).sum(axis=0)
    v = (w[:, None] * vel).sum(axis=0)
    m = (w[:, None, None] * np.array([e.shape for e in ests])).sum(axis=0)
    return TargetEstimate(t_s, c, v, m, own is not None and own.direct)


def ref_landmark_returns(rng: np.random.Generator, rel_m: np.ndarray, normals: np.ndarray, bore: np.ndarray,
                     p: P000Params, vis: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    half = np.radians(p.fov_full_deg / 2)
    if vis is None:
        vis = visible_landmarks(rel_m, normals, bore, p)
    ids = np.flatnonzero(vis)
    ret = rel_m[vis] + rng.normal(0.0, p.noise_m, (len(ids), 3))
    n_out = int(rng.binomial(len(ret), p.outlier_fraction)) if len(ret) else 0
    if n_out:
        dirs = rng.normal(size=(n_out, 3))
        dirs -= np.outer(dirs @ bore, bore)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        ang = rng.uniform(0.0, half, n_out)
        u = np.cos(ang)[:, None] * bore + np.sin(ang)[:, None] * dirs
        ret[:n_out] = u * rng.uniform(1.0, p.range_m, n_out)[:, None]
        ids[:n_out] = -1
    return ret, ids


def ref_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack(
        (
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ),
        axis=-1,
    )


def ref_residuals_and_jacobian(points_t: np.ndarray, sqrt_w: np.ndarray, model: gt.Model,
                           prior: float) -> tuple[np.ndarray, np.ndarray]:
    c, rot, s = model
    d = points_t - c[:, None]
    local = rot.T @ d
    inv_a2 = np.exp(-2.0 * s)
    al = local * inv_a2[:, None]
    q = np.maximum(np.einsum("ik,ik->k", local, al), 1e-12)
    rho = np.sqrt(np.einsum("ik,ik->k", d, d))
    q_h = 1.0 / np.sqrt(q)
    dr_dq2 = sqrt_w * rho * q_h / q          # 2 ∂r/∂q, weighted
    k = points_t.shape[1]
    res = np.empty(k + 3)
    res[:k] = sqrt_w * rho * (1.0 - q_h)
    res[k:] = prior * (s - s.mean())
    jac = np.zeros((9, k + 3))
    jac[:3, :k] = (-(sqrt_w * (1.0 - q_h)) / np.maximum(rho, 1e-12)) * d - dr_dq2 * (rot @ al)
    # (l/a²) × l = (l_y l_z (a_y⁻² − a_z⁻²), l_z l_x (a_z⁻² − a_x⁻²), l_x l_y (a_x⁻² − a_y⁻²))
    jac[3:6, :k] = (dr_dq2 * local[gt._NEXT] * local[gt._AFTER]) * (inv_a2[gt._NEXT] - inv_a2[gt._AFTER])[:, None]
    jac[6:, :k] = -dr_dq2 * local * al
    jac[6:, k:] = prior * (np.eye(3) - 1.0 / 3.0)
    return res, jac


# --- the tests ------------------------------------------------------------------------------------


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _points_and_axes(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Local points and semi-axes reaching every branch of the closest point: general points inside,
    near and outside the surface, zero coordinates (one, two, three), equal axes, tiny coordinates,
    large and tiny ellipsoids."""
    rng = np.random.default_rng(seed)
    axes = rng.uniform(0.3, 5.0, (n, 3)) * 10.0 ** rng.integers(-1, 2, (n, 1))
    axes[::9] = [4.0, 1.3, 1.0]
    axes[4::13] = axes[4::13, :1]  # a sphere
    axes[5::17, 1] = axes[5::17, 2]  # two equal axes
    pts = rng.normal(size=(n, 3)) * axes * rng.choice([0.01, 0.3, 0.9, 0.999999, 1.0, 1.000001, 1.5, 4.0], (n, 1))
    for k in range(3):
        pts[k::7, k] = 0.0
        pts[k + 3::11, [k, (k + 1) % 3]] = 0.0
    pts[::23] = 0.0
    pts[6::29, 0] = 1e-14 * axes[6::29, 0]  # below the zero threshold, but not zero
    pts[1::31] = [3.5, 0.0, 0.0]
    pts[2::37] = -pts[2::37]
    return pts, axes


def test_closest_point_equals_4ef2732s_scalar_and_rows() -> None:
    pts, axes = _points_and_axes(29, 4000)
    rows = cc.closest_points_principal(pts, axes)
    assert _same(rows, ref_closest_points_principal(pts, axes))
    for i in range(0, len(pts), 3):
        got = cc.closest_point_principal(pts[i], axes[i])
        assert _same(got, ref_closest_point_principal(pts[i], axes[i])), i
        assert _same(rows[i], got), i
    assert _same(cc.closest_points_principal(np.zeros((0, 3)), np.zeros((0, 3))), np.zeros((0, 3)))


def test_closest_point_with_nan_equals_4ef2732s() -> None:
    """NaN coordinates or axes: the same NaN rows (or the same exception) as before."""
    a = np.array([2.6, 1.9, 1.4])
    for p, ax in [([np.nan, 1.0, 2.0], a), ([1.0, 2.0, 3.0], [np.nan, 1.9, 1.4]), ([0.0, 1.0, 0.5], [1.9, np.nan, 1.4]),
                  ([np.inf, 0.0, 1.0], a)]:
        try:
            ref = ref_closest_point_principal(np.array(p), np.array(ax))
        except Exception as e:  # noqa: BLE001 - the same exception type then
            with pytest.raises(type(e)):
                cc.closest_point_principal(np.array(p), np.array(ax))
            continue
        assert _same(cc.closest_point_principal(np.array(p), np.array(ax)), ref)


@pytest.mark.parametrize("layout", ["c", "fortran", "mixed"])
def test_surface_frames_equal_4ef2732s(layout: str) -> None:
    """Stacked rotations (every rotation a C-ordered float64 matrix) and the row-by-row fallback
    (a Fortran-ordered one among them): the bits of 4ef2732's `surface_frames`."""
    rng = np.random.default_rng(35)
    pts_local, axes = _points_and_axes(36, 600)
    ells, pts = [], []
    for i in range(len(axes)):
        rot = np.eye(3) if i % 5 == 0 else Rotation.random(random_state=i).as_matrix()
        if layout == "fortran" or (layout == "mixed" and i % 3 == 0):
            rot = np.asfortranarray(rot)
        e = Ellipsoid(rng.uniform(-3.0, 3.0, 3), rot, axes[i])
        ells.append(e)
        pts.append(e.centre_m + rot @ pts_local[i])
    got, ref = cc.surface_frames(ells, np.array(pts)), ref_surface_frames(ells, np.array(pts))
    for g, r in zip(got, ref):
        assert _same(g, r)
    for i in range(0, 600, 7):  # and each row as the scalar `surface_frame` (the per-agent path)
        one = cc.surface_frame(ells[i], pts[i])
        assert _same(np.float64(one[0]), got[0][i]) and _same(one[1], got[1][i]) and _same(one[2], got[2][i]), i
    same = [ells[1]] * 40  # the sensor's case: one ellipsoid for every row
    got, ref = cc.surface_frames(same, np.array(pts[:40])), ref_surface_frames(same, np.array(pts[:40]))
    for g, r in zip(got, ref):
        assert _same(g, r)


def test_surface_frames_stacked_rotations_give_each_rows_product() -> None:
    """`_rotate_rows`: row i of the stacked matmul is `rot[i] @ v[i]` and `rot[i].T @ v[i]`, bit for
    bit, over magnitudes from 1e-6 to 1e6 (the BLAS matrix-vector product of each row)."""
    rng = np.random.default_rng(7)
    rot = Rotation.random(3000, random_state=8).as_matrix()
    v = rng.normal(size=(3000, 3)) * 10.0 ** rng.integers(-6, 7, (3000, 1))
    got, got_t = cc._rotate_rows(rot, v), cc._rotate_rows(rot.transpose(0, 2, 1), v)
    for i in range(3000):
        assert got[i].tobytes() == (rot[i] @ v[i]).tobytes() and got_t[i].tobytes() == (rot[i].T @ v[i]).tobytes(), i


def test_dcm_equals_4ef2732s() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q[3] = [np.nan, 0.0, 1.0, np.inf]
    with np.errstate(invalid="ignore"):  # (inf * 0 in the NaN row)
        for x in (q, q[0], q[:0], q.astype(np.float32), q[0].astype(np.float32), q.reshape(5, 10, 4), q.tolist()[0]):
            assert _same(cc.dcm(x), ref_dcm(x))


def _estimate(rng: np.random.Generator, t: float, direct: bool) -> TargetEstimate:
    a = rng.normal(size=(3, 3))
    return TargetEstimate(t - rng.uniform(0.0, 4.0), rng.normal(size=3) * 3.0, rng.normal(size=3) * 0.02,
                          a @ a.T + np.eye(3), direct)


def test_consensus_equals_4ef2732s() -> None:
    """`consensus` and a `Consensus` kept over steps: the bits of 4ef2732's consensus at every t, for
    none, one and up to 19 neighbours, own or not, direct or relayed."""
    rng = np.random.default_rng(30)
    for trial in range(300):
        t = float(rng.uniform(0.0, 550.0))
        own = None if trial % 4 == 0 else _estimate(rng, t, direct=trial % 3 != 0)
        others = [_estimate(rng, t, direct=False) for _ in range(int(rng.integers(0, 20)))]
        ref = ref_consensus(own, others, t, 0.8)
        got = consensus(own, others, t, 0.8)
        if ref is None:
            assert got is None and Consensus.of(own, others, 0.8) is None
            continue
        assert got is not None
        kept = Consensus.of(own, others, 0.8)
        assert kept is not None and kept.holds(own, list(others), 0.8)
        for dt in (0.0, 0.05, 0.1, 1.0, 3.3):
            ref = ref_consensus(own, others, t + dt, 0.8)
            for g in (consensus(own, others, t + dt, 0.8), kept.at(t + dt)):
                assert g.t_s == ref.t_s and g.direct == ref.direct
                assert _same(g.centre_m, ref.centre_m) and _same(g.velocity_mps, ref.velocity_mps)
                assert _same(g.shape, ref.shape)
        assert not kept.holds(own, others + [others[0]] if others else [_estimate(rng, t, False)], 0.8)
        if others:
            copy = TargetEstimate(others[0].t_s, others[0].centre_m, others[0].velocity_mps, others[0].shape, False)
            assert not kept.holds(own, [copy] + others[1:], 0.8)  # the same values, another estimate
        assert not kept.holds(own, others, 0.7)


def test_consensus_results_do_not_share_arrays() -> None:
    rng = np.random.default_rng(1)
    kept = Consensus.of(_estimate(rng, 5.0, True), [_estimate(rng, 5.0, False)], 0.8)
    assert kept is not None
    a, b = kept.at(5.0), kept.at(5.05)
    assert not np.shares_memory(a.velocity_mps, b.velocity_mps) and not np.shares_memory(a.shape, b.shape)


def test_landmark_returns_equal_4ef2732s() -> None:
    """The outlier directions' projection and normalisation written out as np.outer and
    np.linalg.norm compute them: the same returns, ids and generator state after."""
    p = P000Params()
    lm, nrm = cc.surface_landmarks(np.array([2.6, 1.9, 1.4]), 400)
    rng = np.random.default_rng(4)
    outliers = 0
    for k in range(400):
        r = rng.normal(size=3) * rng.uniform(1.0, 9.0)
        bore = -r / math.sqrt(cc.dot3(r, r)) + rng.normal(size=3) * 0.2
        bore /= math.sqrt(cc.dot3(bore, bore))
        q = P000Params(outlier_fraction=[0.1, 0.5, 1.0, 0.0][k % 4])
        a, b = keyed_rng(1, 0xC0, k, 3), np.random.default_rng([1, 0xC0, k, 3])
        got, ref = landmark_returns(a, lm - r, nrm, bore, q), ref_landmark_returns(b, lm - r, nrm, bore, q)
        assert _same(got[0], ref[0]) and _same(got[1], ref[1]), k
        assert a.bit_generator.state == b.bit_generator.state
        outliers += int((got[1] < 0).sum())
        vis = visible_landmarks(lm - r, nrm, bore, p)
        got = landmark_returns(keyed_rng(2, 0xC0, k, 0), lm - r, nrm, bore, p, vis)
        ref = ref_landmark_returns(np.random.default_rng([2, 0xC0, k, 0]), lm - r, nrm, bore, p, vis)
        assert _same(got[0], ref[0]) and _same(got[1], ref[1]), k
    assert outliers > 100


@pytest.mark.parametrize("key", [(1, 0xC0, 0, 0), (1, 0xC0, 11000, 9), (0, 0, 0, 0), (2**32 - 1, 0xC0, 2**32 - 1, 19),
                                 (2**32, 0xC0, 5, 1), (1, 0xC0, 2**40 + 3, 2), (7,), (np.int64(3), np.uint32(0xC0), 5, 1)])
def test_keyed_rng_is_default_rng_of_the_list(key: tuple[int, ...]) -> None:
    a, b = keyed_rng(*key), np.random.default_rng(list(key))
    assert a.bit_generator.state == b.bit_generator.state
    assert _same(a.normal(size=7), b.normal(size=7)) and a.binomial(50, 0.1) == b.binomial(50, 0.1)


def test_keyed_rng_refuses_negative_keys_as_numpy_does() -> None:
    with pytest.raises(ValueError):
        np.random.default_rng([1, -1])
    with pytest.raises(ValueError):
        keyed_rng(1, -1)


def test_cross_equals_4ef2732s() -> None:
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(20, 3)) * 1e3, rng.normal(size=(20, 3))
    a[0, 1] = np.nan
    for x, y in ((a, b), (a[0], b), (a, b[0]), (a[0], b[0]), (a.reshape(4, 5, 3), b[:5]), (a.astype(np.float32), b),
                 (a[:0], b[:0]), (a.astype(np.float32), b.astype(np.float32)), (np.arange(6).reshape(2, 3), b[:2])):
        assert _same(cross(x, y), ref_cross(x, y))


def test_the_batch_links_packets_are_each_commands(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """`CommandBatch.transmissions(i)` of paper 000's step_batch is `command(i).transmissions` (the
    same packets, in order) at every step of 30 s of capture-10 (landmark packets from ~15 s)."""
    from swarmhil.deploy import batch as deploy_batch
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    send = deploy_batch.BatchLink.send
    seen = [0]

    def checked(self: Any, step: int, rows: np.ndarray, cb: Any) -> None:
        for r in range(len(rows)):
            got, ref = cb.transmissions(r), cb.command(r).transmissions
            assert [(t.type, t.payload, t.dst) for t in got] == [(t.type, t.payload, t.dst) for t in ref], (step, r)
            seen[0] += len(got)
        send(self, step, rows, cb)

    monkeypatch.setattr(deploy_batch.BatchLink, "send", checked)
    sc = load_scenario(ROOT / "deploy" / "scenarios" / "capture-10.toml").with_overrides(duration_s=30.0)
    res = run_in_process(sc, tmp_path, "tx", record="truth")
    assert res.summary["batch"]["used"] and seen[0] > 10


def test_residuals_and_jacobian_equal_4ef2732s() -> None:
    """The GNC-TLS solver's weighted residuals and Jacobian: the bits of 4ef2732's for random
    points, weights and models, and priors of either sign, zero, -0.0 and NaN (its block made once
    per prior object)."""
    rng = np.random.default_rng(11)
    for trial in range(200):
        k = int(rng.integers(1, 250))
        pts = rng.normal(size=(3, k)) * 3.0
        sw = np.sqrt(rng.uniform(0.0, 1.0, k))
        rot = Rotation.random(random_state=trial).as_matrix()
        model = gt.Model(rng.normal(size=3), rot, np.log(rng.uniform(0.3, 5.0, 3)))
        prior = [0.02, 0.02, 1.5, -0.3, 0.0, -0.0, float("nan"), np.float64(0.02)][trial % 8]
        got, ref = gt.residuals_and_jacobian(pts, sw, model, prior), ref_residuals_and_jacobian(pts, sw, model, prior)
        assert _same(got[0], ref[0]) and _same(got[1], ref[1]), trial
