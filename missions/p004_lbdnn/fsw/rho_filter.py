"""The rho-filter of paper 004 eq. 25, in integral form (NOTES-004).

rho = -(k3 + k4) eta_tilde + nu, with nu_dot = (1 - k3^2 - k3 k4) eta_tilde - (k3 + k4 + k5) rho
and nu(0) = (k3 + k4) eta_tilde(0), so that rho(0) = 0. Differentiating gives eq. 34,
rho_dot = eta_tilde - (k3 + k4) r_tilde - k5 rho, without ever differentiating a measurement.
"""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p004_lbdnn.contract import Gains


def rho(eta_tilde: np.ndarray, nu: np.ndarray, g: Gains) -> np.ndarray:
    """rho_i of eq. 25: -(k3 + k4) eta_tilde_i + nu_i (nu_i holds the two integrals)."""
    return -(g.k3 + g.k4) * eta_tilde + nu


def nu_dot(eta_tilde: np.ndarray, rho_i: np.ndarray, g: Gains) -> np.ndarray:
    """d nu_i / dt = (1 - k3^2 - k3 k4) eta_tilde_i - (k3 + k4 + k5) rho_i (integrand of eq. 25)."""
    return (1.0 - g.k3**2 - g.k3 * g.k4) * eta_tilde - (g.k3 + g.k4 + g.k5) * rho_i


def nu_initial(eta_tilde0: np.ndarray, g: Gains) -> np.ndarray:
    """nu_i(0) = (k3 + k4) eta_tilde_i(0), i.e. rho_i(0) = 0 (eq. 25)."""
    return (g.k3 + g.k4) * np.asarray(eta_tilde0, dtype=float)
