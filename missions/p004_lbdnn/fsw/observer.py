"""The distributed observer of paper 004 eq. 26 and the measured relative position error eq. 12.

With the Cartesian inertial reading (NOTES-004) g(q_i) = I, so g_j u_j = u_j.
"""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p004_lbdnn.contract import Gains


def relative_position_error(d_m: np.ndarray, y_m: np.ndarray | None, c: np.ndarray, b: int) -> np.ndarray:
    """eta_i = sum_{j in N_i} d_ij + b_i C_i^T y_i (eq. 12); d_m is (|N_i|, 3), y_m (m_i,) or None."""
    d_m = np.asarray(d_m, dtype=float).reshape(-1, 3)
    eta = d_m.sum(axis=0)
    if b and y_m is not None:
        eta = eta + c.T @ np.asarray(y_m, dtype=float)
    return eta


def input_coupling(u_i: np.ndarray, u_neighbours: np.ndarray, ctc: np.ndarray) -> np.ndarray:
    """sum_{j in N_i} (u_j - u_i) - b_i C_i^T C_i u_i, the first bracket of eq. 26 (g = I).

    u_neighbours is (|N_i|, 3); ctc is b_i C_i^T C_i. This is -(H g u)_i of eq. 33.
    """
    u_neighbours = np.asarray(u_neighbours, dtype=float).reshape(-1, 3)
    return (u_neighbours - u_i).sum(axis=0) - ctc @ u_i


def zeta_hat_dot(coupling: np.ndarray, eta_tilde: np.ndarray, rho_i: np.ndarray, g: Gains) -> np.ndarray:
    """d zeta_hat_i / dt = coupling - (k3^2 - 2) eta_tilde_i - (2 k3 + k4 + k5) rho_i (eq. 26)."""
    return coupling - (g.k3**2 - 2.0) * eta_tilde - (2.0 * g.k3 + g.k4 + g.k5) * rho_i
