"""The control input of paper 004 eq. 27 (g_i = I in the Cartesian inertial reading)."""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p004_lbdnn.contract import Gains


def control(phi: np.ndarray, eta: np.ndarray, zeta_hat: np.ndarray, eta_tilde: np.ndarray,
            rho_i: np.ndarray, g: Gains) -> np.ndarray:
    """u_i = Phi_i(kappa_i, theta_hat_i) + k2 (k1 eta_i + zeta_hat_i - k3 eta_tilde_i - rho_i) (eq. 27)."""
    return phi + g.k2 * (g.k1 * eta + zeta_hat - g.k3 * eta_tilde - rho_i)
