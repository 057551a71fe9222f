"""Robust ellipsoid fit from landmark points: GNC-TLS (paper 000 §3.2.2, ref. [11]: Yang et al.
2020, "Graduated Non-Convexity for Robust Spatial Perception", Algorithm 1 with the TLS weights).

Non-minimal solver: weighted least squares over (centre c, rotation R, log semi-axes s) of the
radial residual r_i = ‖p_i − c‖(1 − 1/√((p_i−c)ᵀM(p_i−c))), the distance in metres along the
ray from the centre to the surface. The parametrisation makes every solution an ellipsoid
(NOTES-000 trap 5: algebraic or Sampson re-weighting can lock onto hyperboloids). A weak prior on
equal log semi-axes (`sphere_prior_m`) keeps a fit from a single patch sphere-like rather than
arbitrary (trap 6); it weighs as one point with that residual per unit of log-axis difference.

The solver is a damped Gauss-Newton (Levenberg-Marquardt) step on the 9 parameters, with the
rotation updated on the manifold, R ← R exp([δ]×), so the Jacobian is analytic in all nine and each
iteration is a handful of numpy operations over the K points (`ellipsoid_lsq`). Two uses:

- `gnc_tls_fit`, the acquisition (cold start, lost track): GNC-TLS from a few robust starts;
- `warm_fit`, the in-loop update: TLS from the previous estimate with a bounded number of
  iterations, converging to the same TLS solution as the cold fit when the previous estimate is
  within the bound (tests/missions/test_p000_units.py, warm = cold).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from swarmhil.missions.p000_capture.contract import Ellipsoid


@dataclass(frozen=True)
class GncSettings:
    noise_bound_m: float = 0.1     # c̄: TLS inlier threshold on the radial residual
    mu_factor: float = 1.4         # μ ← 1.4 μ (Yang et al. 2020)
    max_outer: int = 100
    sphere_prior_m: float = 0.02
    min_points: int = 12
    restarts: int = 3
    inner_iterations: int = 10     # solver iterations per GNC step (warm-started from the last step)
    polish_iterations: int = 50    # solver iterations on the final inliers
    start_bound_m: float = 0.8     # bound of the start stage (sphere GNC, points used from a start)
    warm_iterations: int = 6       # warm fit: solver iterations per TLS stage
    warm_rounds: int = 3           # warm fit: re-weightings at c̄ until the inlier set holds


@dataclass(frozen=True)
class FitResult:
    ellipsoid: Ellipsoid
    inliers: np.ndarray        # (K,) bool: final residual within c̄
    weights: np.ndarray        # (K,)
    outer_iterations: int
    rms_inlier_m: float


class Model(NamedTuple):
    """An ellipsoid as the solver's state: centre c (3,), rotation R (3, 3, columns = principal
    axes), log semi-axes s (3,)."""

    centre_m: np.ndarray
    rotation: np.ndarray
    log_axes: np.ndarray

    @classmethod
    def of(cls, ell: Ellipsoid) -> "Model":
        return cls(np.asarray(ell.centre_m, dtype=float), np.asarray(ell.rotation, dtype=float),
                   np.log(ell.semi_axes_m))

    def ellipsoid(self) -> Ellipsoid:
        return Ellipsoid(self.centre_m, self.rotation, np.exp(self.log_axes))


def rotvec_matrix(phi: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation matrix exp([φ]×) of rotation vector φ."""
    angle = float(np.sqrt(phi @ phi))
    if angle < 1e-12:
        return np.eye(3)
    k = phi / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def radial_residuals(points_m: np.ndarray, model: Model) -> np.ndarray:
    """r_i = ‖p−c‖(1 − 1/√q), q = (p−c)ᵀM(p−c): signed distance along the ray from the centre."""
    d = points_m - model.centre_m
    local = (d @ model.rotation) * np.exp(-model.log_axes)
    rho = np.sqrt(np.einsum("ij,ij->i", d, d))
    q = np.einsum("ij,ij->i", local, local)
    return rho * (1.0 - 1.0 / np.sqrt(np.maximum(q, 1e-12)))


def residuals_and_jacobian(points_t: np.ndarray, sqrt_w: np.ndarray, model: Model,
                           prior: float) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residuals (K + 3,) — the K radial ones, then the sphere prior prior·(s − mean s) —
    and their Jacobian, transposed (9, K + 3), in (δc, δ, δs) with R ← R exp([δ]×):

        ∂r/∂c = −(1 − q^-½) d/ρ − ρ q^-3/2 R (l/a²),   l = Rᵀd, d = p − c, ρ = ‖d‖, q = lᵀ(l/a²)
        ∂r/∂δ = ρ q^-3/2 (l/a²) × l
        ∂r/∂s_k = −ρ q^-3/2 l_k²/a_k²

    `points_t` is (3, K): the points as rows of coordinates, so every term is a row operation.
    """
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
    res[k:] = prior * (s - np.add.reduce(s) / 3.0)  # (s.mean(): the same sum and division)
    jac = np.zeros((9, k + 3))
    jac[:3, :k] = (-(sqrt_w * (1.0 - q_h)) / np.maximum(rho, 1e-12)) * d - dr_dq2 * (rot @ al)
    # (l/a²) × l = (l_y l_z (a_y⁻² − a_z⁻²), l_z l_x (a_z⁻² − a_x⁻²), l_x l_y (a_x⁻² − a_y⁻²))
    jac[3:6, :k] = (dr_dq2 * local[_NEXT] * local[_AFTER]) * (inv_a2[_NEXT] - inv_a2[_AFTER])[:, None]
    jac[6:, :k] = -dr_dq2 * local * al
    jac[6:, k:] = _prior_block(prior)
    return res, jac


def _prior_block(prior: float) -> np.ndarray:
    """prior·(I − 1/3), the sphere prior's Jacobian block, made once for the last prior weight (the
    same object: a fit's settings; another, even of equal value, makes its own: -0.0, NaN)."""
    global _PRIOR_BLOCK
    if _PRIOR_BLOCK is None or _PRIOR_BLOCK[0] is not prior:
        block = prior * (np.eye(3) - 1.0 / 3.0)
        block.flags.writeable = False
        _PRIOR_BLOCK = (prior, block)
    return _PRIOR_BLOCK[1]


_PRIOR_BLOCK: tuple[float, np.ndarray] | None = None


_NEXT = np.array([1, 2, 0])
_AFTER = np.array([2, 0, 1])


def _moved(model: Model, step: np.ndarray) -> Model:
    return Model(model.centre_m + step[:3], model.rotation @ rotvec_matrix(step[3:6]), model.log_axes + step[6:])


def ellipsoid_lsq(points_m: np.ndarray, weights: np.ndarray, model: Model, prior: float,
                  max_iterations: int) -> Model:
    """The non-minimal solver: weighted nonlinear least squares from `model`, at most
    `max_iterations` accepted Levenberg-Marquardt steps (H + λ diag H) δ = −Jᵀr; stops when the
    cost falls by less than 1e-10 of itself. Points of zero weight are left out."""
    keep = weights > 0.0
    pts = points_m[keep].T
    sw = np.sqrt(weights[keep])
    res, jac = residuals_and_jacobian(pts, sw, model, prior)
    cost = float(res @ res)
    lam = 1e-3
    accepted = 0
    while accepted < max_iterations:
        h = jac @ jac.T
        g = jac @ res
        try:
            step = np.linalg.solve(h + lam * np.diag(np.diag(h) + 1e-12), -g)
        except np.linalg.LinAlgError:
            break
        trial = _moved(model, step)
        res_t, jac_t = residuals_and_jacobian(pts, sw, trial, prior)
        cost_t = float(res_t @ res_t)
        if cost_t < cost:
            done = cost - cost_t <= 1e-10 * cost
            model, res, jac, cost = trial, res_t, jac_t, cost_t
            lam = max(lam / 3.0, 1e-9)
            accepted += 1
            if done:
                break
        else:
            lam *= 4.0
            if lam > 1e8:
                break
    return model


def sphere_fit(points_m: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Linear (algebraic) sphere fit ‖p‖² = 2cᵀp + (ρ² − ‖c‖²): the initial guess."""
    w = np.ones(len(points_m)) if weights is None else weights
    a = np.hstack((2.0 * points_m, np.ones((len(points_m), 1)))) * w[:, None] ** 0.5
    b = np.sum(points_m ** 2, axis=1) * w ** 0.5
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    c = sol[:3]
    rho2 = sol[3] + c @ c
    return c, float(np.sqrt(max(rho2, 1e-6)))


def tls_weights(r2: np.ndarray, c2: float, mu: float) -> np.ndarray:
    """Closed-form GNC-TLS weight update (Yang et al. 2020, Prop. 2)."""
    w = np.empty_like(r2)
    lo = mu / (mu + 1.0) * c2
    hi = (mu + 1.0) / mu * c2
    w[r2 <= lo] = 1.0
    w[r2 >= hi] = 0.0
    mid = (r2 > lo) & (r2 < hi)
    w[mid] = np.sqrt(c2 * mu * (mu + 1.0) / r2[mid]) - mu
    return np.clip(w, 0.0, 1.0)


def gnc_tls(residual_fn, solve_fn, model, n_points: int, noise_bound_m: float,
            mu_factor: float, max_outer: int, active: np.ndarray | None = None,
            r2max: float | None = None):
    """Yang et al. 2020 Algorithm 1 with TLS weights, over any weighted non-minimal solver.

    residual_fn(model) -> (K,) residuals in metres; solve_fn(weights, model) -> model.
    `active` (bool mask) restricts the largest residual that sets μ0 = c̄²/(2 r²_max − c̄²) to the
    points of a previous stage. Returns (model, binary inlier weights, outer iterations).
    """
    c2 = noise_bound_m ** 2
    r2 = residual_fn(model) ** 2
    r2_max = float(r2[active].max()) if active is not None and active.any() else float(r2.max())
    if r2max is not None:
        r2_max = r2max
    if r2_max <= c2:
        return model, (r2 <= c2).astype(float), 0
    mu = c2 / (2.0 * r2_max - c2)
    it = 0
    for it in range(1, max_outer + 1):
        # IRLS floor: residuals below c̄/3 (the noise) weigh as c̄/3, or the few points that happen
        # to sit on the current model take all the weight at small μ and the fit locks onto them
        w = tls_weights(np.maximum(r2, c2 / 9.0), c2, mu)
        if w.max() <= 0.0:
            raise ValueError(f"GNC-TLS lost every point (noise bound {noise_bound_m} m)")
        model = solve_fn(w / w.max(), model)  # relative weights; keeps a prior's weight fixed
        r2 = residual_fn(model) ** 2
        if np.sum(w * (1.0 - w)) < 1e-6 * n_points:  # weights binary: converged
            break
        mu *= mu_factor
    return model, (r2 <= c2).astype(float), it


def _sphere_stage(pts: np.ndarray, bound_m: float, s: GncSettings) -> tuple[np.ndarray, np.ndarray]:
    """GNC-TLS over the linear sphere fit: (centre, radius) packed as 4 numbers, inlier mask."""
    sphere = np.append(*sphere_fit(pts))
    sphere, w, _ = gnc_tls(lambda m: np.linalg.norm(pts - m[:3], axis=1) - m[3],
                           lambda w, m: np.append(*sphere_fit(pts, w)),
                           sphere, len(pts), bound_m, s.mu_factor, s.max_outer)
    return sphere, w > 0.5


def _two_cap_start(s1: np.ndarray, s2: np.ndarray) -> Ellipsoid:
    """An elongated start spanning two spheres (the two ends a TLS sphere locks onto)."""
    axis = s2[:3] - s1[:3]
    half = 0.5 * float(np.linalg.norm(axis))
    e1 = axis / max(2.0 * half, 1e-9)
    e2 = np.cross(e1, [1.0, 0.0, 0.0] if abs(e1[0]) < 0.9 else [0.0, 1.0, 0.0])
    e2 /= np.linalg.norm(e2)
    rot = np.stack([e1, e2, np.cross(e1, e2)], axis=1)
    r = 0.5 * (s1[3] + s2[3])
    return Ellipsoid(0.5 * (s1[:3] + s2[:3]), rot, np.array([half + r, r, r]))


def moment_start(points_m: np.ndarray) -> Ellipsoid:
    """Ellipsoid with the points' mean and covariance (surface points: E[x_k²] ≈ a_k²/3)."""
    c = points_m.mean(axis=0)
    eig, vec = np.linalg.eigh(np.cov((points_m - c).T))
    return Ellipsoid(c, vec, np.sqrt(3.0 * np.maximum(eig, 1e-4)))


def _result(pts: np.ndarray, model: Model, noise_bound_m: float, outer_iterations: int) -> FitResult:
    r2 = radial_residuals(pts, model) ** 2
    inl = r2 <= noise_bound_m ** 2
    rms = float(np.sqrt(np.mean(r2[inl]))) if inl.any() else float("inf")
    return FitResult(model.ellipsoid(), inl, inl.astype(float), outer_iterations, rms)


def _points(points_m: np.ndarray, settings: GncSettings) -> np.ndarray:
    pts = np.asarray(points_m, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < settings.min_points:
        raise ValueError(f"need at least {settings.min_points} points (K, 3), got shape {pts.shape}")
    return pts


def gnc_tls_fit(points_m: np.ndarray, settings: GncSettings = GncSettings(),
                initial: Ellipsoid | None = None) -> FitResult:
    """Fit an ellipsoid to points with outliers by GNC-TLS from a few starts; keep the lowest
    TLS cost Σ min(r², c̄²).

    Starts: `initial` (the previous estimate) if given; else a GNC-TLS sphere (linear, globally
    solved, bound `start_bound_m`); the moments of that sphere's inliers (a slender target lies
    along a large TLS sphere); and, when the points left out by it hold another sphere,
    an elongated start spanning both (a TLS sphere locks onto one end of an elongated target).
    From each start: the ellipsoid-only nonlinear solver on the points within `start_bound_m`,
    then GNC-TLS over it with μ0 set by the largest residual among those points.
    (A general quadric as the non-minimal solver fits outlier-laden data with hyperboloids.)
    """
    pts = _points(points_m, settings)
    k = len(pts)
    c2 = settings.noise_bound_m ** 2

    def residual(model: Model) -> np.ndarray:
        return radial_residuals(pts, model)

    def solve(w: np.ndarray, model: Model, iterations: int = settings.inner_iterations) -> Model:
        return ellipsoid_lsq(pts, w, model, settings.sphere_prior_m, iterations)

    starts: list[Ellipsoid] = []
    if initial is not None:
        starts.append(initial)
    else:
        s1, in1 = _sphere_stage(pts, settings.start_bound_m, settings)
        starts.append(Ellipsoid(s1[:3], np.eye(3), np.full(3, s1[3])))
        starts.append(moment_start(pts[in1]))
        rest = pts[~in1]
        if len(rest) >= settings.min_points:
            s2, in2 = _sphere_stage(rest, settings.start_bound_m, settings)
            if in2.sum() >= settings.min_points:
                starts.append(_two_cap_start(s1, s2))
    best: tuple[float, Model, int] | None = None

    def run(start: Model) -> tuple[float, Model, int] | None:
        active = np.abs(residual(start)) <= settings.start_bound_m
        if active.sum() < settings.min_points:
            return None
        model = solve(active.astype(float), start)
        model, w, it = gnc_tls(residual, solve, model, k, settings.noise_bound_m, settings.mu_factor,
                               settings.max_outer, active)
        if w.sum() >= settings.min_points:  # polish on the inliers
            model = solve(w, model, settings.polish_iterations)
        return float(np.sum(np.minimum(residual(model) ** 2, c2))), model, it

    for start in starts:
        model = Model.of(start)
        for _ in range(settings.restarts + 1):  # restart from the result while the TLS cost drops
            got = run(model)
            if got is None or (best is not None and got[0] >= best[0]):
                break
            best = got
            model = got[1]
    if best is None:
        raise ValueError(f"no start kept {settings.min_points} points within {settings.start_bound_m} m")
    return _result(pts, best[1], settings.noise_bound_m, best[2])


def warm_fit(points_m: np.ndarray, previous: Ellipsoid, settings: GncSettings = GncSettings()) -> FitResult:
    """The in-loop update, warm-started from the previous estimate: truncated least squares with the
    bound shrunk in two steps (3c̄, then c̄) instead of the full GNC schedule, then re-weighted at c̄
    until the inlier set holds (≤ `warm_rounds`), each solve ≤ `warm_iterations` iterations.

    Its fixed point is the cold fit's (`gnc_tls_fit`: TLS at c̄, polished on its inliers) when the
    previous estimate lies within the bound of it. Raises ValueError ("track lost") when fewer than
    `min_points` points lie within a stage's bound of the estimate: the caller falls back to
    `gnc_tls_fit`, the acquisition.
    """
    pts = _points(points_m, settings)
    model = Model.of(previous)
    c_bar = settings.noise_bound_m
    inl = None
    for bound in [3.0 * c_bar] + [c_bar] * settings.warm_rounds:
        w = np.abs(radial_residuals(pts, model)) <= bound
        if w.sum() < settings.min_points:
            raise ValueError(f"track lost: {int(w.sum())} points within {bound} m of the previous estimate")
        if bound == c_bar and inl is not None and np.array_equal(w, inl):
            break
        inl = w if bound == c_bar else None
        model = ellipsoid_lsq(pts, w.astype(float), model, settings.sphere_prior_m, settings.warm_iterations)
    return _result(pts, model, c_bar, 0)
