"""Collision threats (eq. 7 and 8) and their gradients.

The threat of a sphere of combined radius R at offset d is φ(d) = 1/(|d|^2 - R^2)^h; inside the
sphere (|d| <= R) it is undefined, so |d|^2 - R^2 is floored at `floor_m2` (guard, NOTES-003).
"""
from __future__ import annotations

import numpy as np


def _gap_m2(d: np.ndarray, radius_m: np.ndarray, floor_m2: float) -> tuple[np.ndarray, np.ndarray]:
    raw = np.einsum("...i,...i->...", d, d) - np.asarray(radius_m) ** 2
    return np.maximum(raw, floor_m2), raw > floor_m2


def barrier(d: np.ndarray, radius_m: np.ndarray, h: float, floor_m2: float) -> np.ndarray:
    """φ(d) = (|d|^2 - R^2)^-h, d (..., 3), R broadcasting with d[..., 0]."""
    gap, _ = _gap_m2(d, radius_m, floor_m2)
    return gap ** (-h)


def barrier_grad(d: np.ndarray, radius_m: np.ndarray, h: float, floor_m2: float) -> np.ndarray:
    """∇_d φ = -2 h d (|d|^2 - R^2)^-(h+1) (zero where the floor holds), shape of d."""
    gap, live = _gap_m2(d, radius_m, floor_m2)
    scale = np.where(live, -2.0 * h * gap ** (-(h + 1.0)), 0.0)
    return scale[..., None] * d


def structure_threat(p_m: np.ndarray, centres_m: np.ndarray, radii_m: np.ndarray, r_i_m: float,
                     h: float, floor_m2: float) -> np.ndarray:
    """c_Cg,i = Σ_g 1/(|q_Li - q_Cg|^2 - (r_i + r_g)^2)^h (eq. 8); p (..., 3) -> (...)."""
    d = np.asarray(p_m)[..., None, :] - centres_m
    return np.sum(barrier(d, r_i_m + radii_m, h, floor_m2), axis=-1)


def structure_threat_grad(p_m: np.ndarray, centres_m: np.ndarray, radii_m: np.ndarray, r_i_m: float,
                          h: float, floor_m2: float) -> np.ndarray:
    """∂c_Cg,i/∂q_Li; p (..., 3) -> (..., 3)."""
    d = np.asarray(p_m)[..., None, :] - centres_m
    return np.sum(barrier_grad(d, r_i_m + radii_m, h, floor_m2), axis=-2)


def pair_threats(p_m: np.ndarray, r_m: np.ndarray, h: float, floor_m2: float) -> np.ndarray:
    """c_FC,i = Σ_{j≠i} 1/(|q_Li - q_Lj|^2 - (r_i + r_j)^2)^h (eq. 7), for all i: (N,)."""
    d = p_m[:, None, :] - p_m[None, :, :]
    radius = r_m[:, None] + r_m[None, :]
    phi = barrier(d, radius, h, floor_m2)
    np.fill_diagonal(phi, 0.0)
    return phi.sum(axis=1)


def pair_threat_grads(p_m: np.ndarray, r_m: np.ndarray, h: float, floor_m2: float) -> np.ndarray:
    """G[i, j] = ∇φ(q_Li - q_Lj) (zero on the diagonal), (N, N, 3).

    ∂c_FC,i/∂q_Li = Σ_j G[i, j] and ∂c_FC,k/∂q_Li = G[i, k] (k ≠ i), since ∇φ is odd.
    """
    d = p_m[:, None, :] - p_m[None, :, :]
    radius = r_m[:, None] + r_m[None, :]
    grad = barrier_grad(d, radius, h, floor_m2)
    idx = np.arange(len(p_m))
    grad[idx, idx, :] = 0.0
    return grad
