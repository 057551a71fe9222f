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

from .ellipsoid import Ellipsoid


@dataclass(frozen=True)
class GncSettings:
    noise_bound_m: float = 0.1     # c̄: TLS inlier threshold on the radial residual
    mu_factor: float = 1.4         # μ ← 1.4 μ (Yang et al. 2020)
    max_outer: int = 100
    sphere_prior_m: float = 0.02
    min_points: int = 12
    sphere_bound_fraction: float = 0.35  # stage-1 bound, as a fraction of the point spread


@dataclass(frozen=True)
class FitResult:
    ellipsoid: Ellipsoid
    inliers: np.ndarray        # (K,) bool: final TLS weight > 0.5
    weights: np.ndarray        # (K,)
    outer_iterations: int
    rms_inlier_m: float


def _unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c = theta[:3]
    rot = Rotation.from_rotvec(theta[3:6]).as_matrix()
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
    rho = np.linalg.norm(local, axis=1)
    q = np.sum((local / axes) ** 2, axis=1)
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


def weighted_ellipsoid_fit(points_m: np.ndarray, weights: np.ndarray, theta0: np.ndarray,
                           sphere_prior_m: float) -> np.ndarray:
    """The non-minimal solver: weighted nonlinear least squares from `theta0`."""
    sol = least_squares(_residuals, theta0, args=(points_m, np.sqrt(weights), sphere_prior_m),
                        method="lm", xtol=1e-6, ftol=1e-8, max_nfev=400)
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
            mu_factor: float, max_outer: int):
    """Yang et al. 2020 Algorithm 1 with TLS weights, over any weighted non-minimal solver.

    residual_fn(model) -> (K,) residuals in metres; solve_fn(weights, model) -> model.
    Returns (model, weights, outer iterations).
    """
    c2 = noise_bound_m ** 2
    r2 = residual_fn(model) ** 2
    w = np.ones(n_points)
    if r2.max() <= c2:
        return model, w, 0
    mu = c2 / (2.0 * float(r2.max()) - c2)
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


def gnc_tls_fit(points_m: np.ndarray, settings: GncSettings = GncSettings(),
                initial: Ellipsoid | None = None) -> FitResult:
    """Fit an ellipsoid to points with outliers by GNC-TLS, in two graduated stages.

    1. GNC-TLS over the linear sphere fit (4 unknowns, well posed even on one patch) with a
       loose bound, to drop the gross outliers; 2. GNC-TLS over the ellipsoid-only nonlinear
       solver (radial residual), started from that sphere or from `initial`.
    (A general quadric as the non-minimal solver fits outlier-laden data with hyperboloids.)
    """
    pts = np.asarray(points_m, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < settings.min_points:
        raise ValueError(f"need at least {settings.min_points} points (K, 3), got shape {pts.shape}")
    k = len(pts)
    if initial is None:
        c0, rho0 = sphere_fit(pts)
        sphere = np.concatenate((c0, [rho0]))
        spread = float(np.max(np.linalg.norm(pts - np.median(pts, axis=0), axis=1)))
        sphere, w, _ = gnc_tls(
            lambda m: np.linalg.norm(pts - m[:3], axis=1) - m[3],
            lambda w, m: np.append(*sphere_fit(pts, w)),
            sphere, k, max(settings.sphere_bound_fraction * spread, settings.noise_bound_m),
            settings.mu_factor, settings.max_outer)
        theta0 = np.concatenate((sphere[:3], np.zeros(3), np.full(3, np.log(sphere[3]))))
    else:
        theta0 = theta_from(initial)

    def residual(theta: np.ndarray) -> np.ndarray:
        c, rot, axes = _unpack(theta)
        return radial_residuals(pts, c, rot @ np.diag(axes ** -2.0) @ rot.T)

    theta, w, it = gnc_tls(residual,
                           lambda w, th: weighted_ellipsoid_fit(pts, w, th, settings.sphere_prior_m),
                           theta0, k, settings.noise_bound_m, settings.mu_factor, settings.max_outer)
    theta = weighted_ellipsoid_fit(pts, w, theta, settings.sphere_prior_m)  # polish on the inliers
    c, rot, axes = _unpack(theta)
    r2 = residual(theta) ** 2
    inl = r2 <= settings.noise_bound_m ** 2
    rms = float(np.sqrt(np.mean(r2[inl]))) if inl.any() else float("inf")
    return FitResult(Ellipsoid(c, rot, axes), inl, inl.astype(float), it, rms)
