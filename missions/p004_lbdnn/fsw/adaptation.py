"""The adaptation law of paper 004 eq. 28: gradient term, weight consensus, projection.

Eq. 28 as printed multiplies the 3 x p Jacobian by a 3-vector; the law that cancels the
theta_tilde^T grad Phi^T r term of eq. 48 uses the transpose, grad_theta Phi^T (zeta_hat + k1 eta)
(NOTES-004). The consensus term k6 (theta_hat_i - sum_j (theta_hat_j - theta_hat_i)) is the
i-th block of k6 ((L + I) kron I_p) theta_hat (eq. 45).
"""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p004_lbdnn.contract import Gains


def adaptation_direction(jac: np.ndarray, zeta_hat: np.ndarray, eta: np.ndarray, theta_i: np.ndarray,
                         theta_neighbours: np.ndarray, g: Gains) -> np.ndarray:
    """Theta_i of eq. 28 (transposed Jacobian):
    Gamma (grad Phi^T (zeta_hat + k1 eta) - k6 ((1 + |N_i|) theta_i - sum_j theta_j))."""
    theta_neighbours = np.asarray(theta_neighbours, dtype=float).reshape(-1, theta_i.size)
    consensus = (1 + theta_neighbours.shape[0]) * theta_i - theta_neighbours.sum(axis=0)
    return g.gamma * (jac.T @ (zeta_hat + g.k1 * eta) - g.k6 * consensus)


def projection(direction: np.ndarray, theta: np.ndarray, theta_bar: float, epsilon: float) -> np.ndarray:
    """Smooth projection onto ||theta|| <= theta_bar (Krstic et al. 1995, App. E; Gamma = gamma I).

    P(theta) = ||theta||^2 - theta_bar^2. Inside the ball, or pointing inwards, the direction is
    unchanged; in the boundary layer theta_bar < ||theta|| <= theta_bar + epsilon its outward
    radial part is removed in proportion c = min(1, P / (epsilon^2 + 2 epsilon theta_bar)), so
    theta_hat stays in the ball of radius theta_bar + epsilon.
    """
    p = float(theta @ theta) - theta_bar**2
    outward = float(theta @ direction)
    if p <= 0.0 or outward <= 0.0:
        return direction
    c = min(1.0, p / (epsilon**2 + 2.0 * epsilon * theta_bar))
    return direction - c * outward / float(theta @ theta) * theta


def clip_to_ball(theta: np.ndarray, radius: float) -> np.ndarray:
    """Radial clip after each integration step: a multi-stage integrator can creep past the
    projection's boundary layer through tangential steps (NOTES-004 "Projection")."""
    norm = float(np.linalg.norm(theta))
    return theta if norm <= radius else theta * (radius / norm)
