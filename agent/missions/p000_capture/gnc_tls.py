"""Robust ellipsoid fit from landmark points: GNC-TLS (paper 000 §3.2.2, ref. [11]: Yang et al.
2020, "Graduated Non-Convexity for Robust Spatial Perception", Algorithm 1 with the TLS weights).

Non-minimal solver: weighted least squares over (centre, rotation vector, log semi-axes) of the
radial residual r_i = ‖p_i − c‖(1 − 1/√((p_i−c)ᵀM(p_i−c))), the distance in metres along the
ray from the centre to the surface. The parametrisation makes every solution an ellipsoid
(NOTES-000 trap 5: algebraic or Sampson re-weighting can lock onto hyperboloids). A weak prior on
equal log semi-axes (`sphere_prior_m`) keeps a fit from a single patch sphere-like rather than
arbitrary (trap 6); it weighs as one point with that residual per unit of log-axis difference.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from missions.p000_capture.contract import Ellipsoid


@dataclass(frozen=True)
class GncSettings:
    noise_bound_m: float = 0.1     # c̄: TLS inlier threshold on the radial residual
    mu_factor: float = 1.4         # μ ← 1.4 μ (Yang et al. 2020)
    max_outer: int = 100
    sphere_prior_m: float = 0.02
    min_points: int = 12
    restarts: int = 3
    inner_nfev: int = 30           # solver evaluations per GNC step (warm-started)
    start_bound_m: float = 0.8    # bound of the start stage (sphere GNC, points used from a start)


@dataclass(frozen=True)
class FitResult:
    ellipsoid: Ellipsoid
    inliers: np.ndarray        # (K,) bool: final TLS weight > 0.5
    weights: np.ndarray        # (K,)
    outer_iterations: int
    rms_inlier_m: float


def rotvec_matrix(phi: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation matrix of rotation vector φ."""
    angle = float(np.sqrt(phi @ phi))
    if angle < 1e-12:
        return np.eye(3)
    k = phi / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def _unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c = theta[:3]
    rot = rotvec_matrix(theta[3:6])
    axes = np.exp(theta[6:9])
    return c, rot, axes


def radial_residuals(points_m: np.ndarray, centre_m: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """r_i = ‖p−c‖(1 − 1/√q), q = (p−c)ᵀM(p−c): signed distance along the ray from the centre."""
    d = points_m - centre_m
    rho = np.linalg.norm(d, axis=1)
    q = np.einsum("ij,jk,ik->i", d, shape, d)
    return rho * (1.0 - 1.0 / np.sqrt(np.maximum(q, 1e-12)))


def _residuals(theta: np.ndarray, pts: np.ndarray, sqrt_w: np.ndarray, prior: float) -> np.ndarray:
    c, rot, axes = _unpack(theta)
    local = (pts - c) @ rot
    rho = np.sqrt(np.einsum("ij,ij->i", local, local))
    scaled = local / axes
    q = np.einsum("ij,ij->i", scaled, scaled)
    r = rho * (1.0 - 1.0 / np.sqrt(np.maximum(q, 1e-12)))
    s = theta[6:9]
    return np.concatenate((sqrt_w * r, prior * (s - s.mean())))


def sphere_fit(points_m: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Linear (algebraic) sphere fit ‖p‖² = 2cᵀp + (ρ² − ‖c‖²): the initial guess."""
    w = np.ones(len(points_m)) if weights is None else weights
    a = np.hstack((2.0 * points_m, np.ones((len(points_m), 1)))) * w[:, None] ** 0.5
    b = np.sum(points_m ** 2, axis=1) * w ** 0.5
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    c = sol[:3]
    rho2 = sol[3] + c @ c
    return c, float(np.sqrt(max(rho2, 1e-6)))


def _jacobian(theta: np.ndarray, pts: np.ndarray, sqrt_w: np.ndarray, prior: float) -> np.ndarray:
    """∂residual/∂θ: analytic for the centre and log axes, forward differences for the rotation."""
    c, rot, axes = _unpack(theta)
    d = pts - c
    local = d @ rot
    rho = np.sqrt(np.einsum("ij,ij->i", d, d))
    al = local / axes ** 2
    q = np.maximum(np.einsum("ij,ij->i", local, al), 1e-12)
    dr_drho = 1.0 - q ** -0.5
    dr_dq = 0.5 * rho * q ** -1.5
    jac = np.zeros((len(pts) + 3, 9))
    jac[:-3, :3] = (-dr_drho / np.maximum(rho, 1e-12))[:, None] * d + (dr_dq[:, None] * (-2.0 * al @ rot.T))
    jac[:-3, 6:] = (-2.0 * dr_dq)[:, None] * local * al
    jac[:-3, :3] *= sqrt_w[:, None]
    jac[:-3, 6:] *= sqrt_w[:, None]
    base = _residuals(theta, pts, sqrt_w, prior)[:-3]
    for k in range(3, 6):
        th = theta.copy()
        th[k] += 1e-7
        jac[:-3, k] = (_residuals(th, pts, sqrt_w, prior)[:-3] - base) / 1e-7
    jac[-3:, 6:] = prior * (np.eye(3) - 1.0 / 3.0)
    return jac


def weighted_ellipsoid_fit(points_m: np.ndarray, weights: np.ndarray, theta0: np.ndarray,
                           sphere_prior_m: float, max_nfev: int = 200) -> np.ndarray:
    """The non-minimal solver: weighted nonlinear least squares from `theta0`."""
    sol = least_squares(_residuals, theta0, jac=_jacobian, args=(points_m, np.sqrt(weights), sphere_prior_m),
                        method="trf", max_nfev=max_nfev)
    return sol.x


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


def theta_from(ell: Ellipsoid) -> np.ndarray:
    rot = ell.rotation if np.linalg.det(ell.rotation) > 0 else ell.rotation * np.array([1, 1, -1])
    return np.concatenate((ell.centre_m, Rotation.from_matrix(rot).as_rotvec(), np.log(ell.semi_axes_m)))


def quadric_fit(points_m: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted algebraic quadric fit with trace(M) = 1 (linear, globally optimal for its cost).

    Returns (M (3,3), g (3,), j) packed as 10 numbers: Q(p) = pᵀMp + 2gᵀp + j.
    """
    x, y, z = points_m.T
    design = np.stack([x * x - z * z, y * y - z * z, 2 * x * y, 2 * x * z, 2 * y * z,
                       2 * x, 2 * y, 2 * z, np.ones_like(x)], axis=1)
    sw = np.sqrt(weights)
    sol, *_ = np.linalg.lstsq(design * sw[:, None], -(z * z) * sw, rcond=None)
    a, b, d, e, f, g, h, i, j = sol
    return np.array([a, b, 1.0 - a - b, d, e, f, g, h, i, j])


def _quadric_parts(qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    a, b, c, d, e, f, g, h, i, j = qd
    return np.array([[a, d, e], [d, b, f], [e, f, c]]), np.array([g, h, i]), float(j)


def sampson_residuals(points_m: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First-order geometric distance Q(p)/‖∇Q(p)‖ to a quadric (metres), and ‖∇Q(p)‖."""
    m, g, j = _quadric_parts(qd)
    mp = points_m @ m
    q = np.einsum("ij,ij->i", mp, points_m) + 2.0 * points_m @ g + j
    grad = np.maximum(np.linalg.norm(2.0 * (mp + g), axis=1), 1e-9)
    return q / grad, grad


def quadric_to_ellipsoid(qd: np.ndarray) -> Ellipsoid | None:
    """The ellipsoid of a quadric, or None if the quadric is not a (real) ellipsoid."""
    m, g, j = _quadric_parts(qd)
    try:
        c = -np.linalg.solve(m, g)
    except np.linalg.LinAlgError:
        return None
    k = float(c @ m @ c - j)
    if k == 0.0:
        return None
    shape = m / k
    if np.linalg.eigvalsh(shape)[0] <= 0.0:
        return None
    return Ellipsoid.from_shape_matrix(c, shape)


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
    pts = np.asarray(points_m, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < settings.min_points:
        raise ValueError(f"need at least {settings.min_points} points (K, 3), got shape {pts.shape}")
    k = len(pts)
    c2 = settings.noise_bound_m ** 2

    def residual(theta: np.ndarray) -> np.ndarray:
        c, rot, axes = _unpack(theta)
        return radial_residuals(pts, c, rot @ np.diag(axes ** -2.0) @ rot.T)

    def solve(w: np.ndarray, theta: np.ndarray, max_nfev: int = settings.inner_nfev) -> np.ndarray:
        return weighted_ellipsoid_fit(pts, w, theta, settings.sphere_prior_m, max_nfev)

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
    best: tuple[float, np.ndarray, int] | None = None

    def run(start: Ellipsoid) -> tuple[float, np.ndarray, int] | None:
        theta0 = theta_from(start)
        active = np.abs(residual(theta0)) <= settings.start_bound_m
        if active.sum() < settings.min_points:
            return None
        theta0 = solve(active.astype(float), theta0)
        theta, w, it = gnc_tls(residual, solve, theta0, k, settings.noise_bound_m, settings.mu_factor,
                               settings.max_outer, active)
        theta = solve(w, theta, 200) if w.sum() >= settings.min_points else theta  # polish on the inliers
        return float(np.sum(np.minimum(residual(theta) ** 2, c2))), theta, it

    for start in starts:
        for _ in range(settings.restarts + 1):  # restart from the result while the TLS cost drops
            got = run(start)
            if got is None or (best is not None and got[0] >= best[0]):
                break
            best = got
            start = Ellipsoid(*_unpack(got[1]))
    if best is None:
        raise ValueError(f"no start kept {settings.min_points} points within {settings.start_bound_m} m")
    _, theta, it = best
    c, rot, axes = _unpack(theta)
    r2 = residual(theta) ** 2
    inl = r2 <= c2
    rms = float(np.sqrt(np.mean(r2[inl]))) if inl.any() else float("inf")
    return FitResult(Ellipsoid(c, rot, axes), inl, inl.astype(float), it, rms)


def track_fit(points_m: np.ndarray, previous: Ellipsoid, settings: GncSettings = GncSettings()) -> FitResult:
    """Cheap update from the previous estimate: TLS with the bound shrunk in two steps
    (3c̄, then c̄) instead of the full GNC schedule. Used while the previous estimate
    still explains most points; `gnc_tls_fit` is the acquisition (cold start, lost track)."""
    pts = np.asarray(points_m, dtype=float)
    theta = theta_from(previous)
    for bound in (3.0 * settings.noise_bound_m, settings.noise_bound_m):
        c, rot, axes = _unpack(theta)
        r = radial_residuals(pts, c, rot @ np.diag(axes ** -2.0) @ rot.T)
        w = (np.abs(r) <= bound).astype(float)
        if w.sum() < settings.min_points:
            raise ValueError(f"track lost: {int(w.sum())} points within {bound} m of the previous estimate")
        theta = weighted_ellipsoid_fit(pts, w, theta, settings.sphere_prior_m, settings.inner_nfev)
    c, rot, axes = _unpack(theta)
    r2 = radial_residuals(pts, c, rot @ np.diag(axes ** -2.0) @ rot.T) ** 2
    inl = r2 <= settings.noise_bound_m ** 2
    return FitResult(Ellipsoid(c, rot, axes), inl, inl.astype(float), 0,
                     float(np.sqrt(np.mean(r2[inl]))) if inl.any() else float("inf"))
