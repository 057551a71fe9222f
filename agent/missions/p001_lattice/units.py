"""Normalisation factors of paper 001 (Table 1) and the SI <-> normalised conversions.

Two unit systems live in this room and nowhere else:
- flight dynamics, normalised by the Earth: length l_e, time t_e = 1/omega_e, so the GEO rate is 1;
- the Tersoff-Brenner (TB) module, where distances are divided by the desired side l (R_e = 1)
  and energies by the well depth D_e = 1.
"""
from __future__ import annotations

# Table 1, space-flight dynamics module
EARTH_RADIUS_M = 6.37813e6  # l_e
EARTH_RATE_RADPS = 7.2921e-5  # omega_e; GEO mean motion
T_E_S = 1.0 / EARTH_RATE_RADPS  # t_e
V_E_MPS = EARTH_RADIUS_M / T_E_S  # v_e ~ 465.1 m/s
A_E_MPS2 = V_E_MPS / T_E_S  # a_e ~ 0.0339 m/s^2

# Table 1, TB module (only their ratio enters eq. 14)
CARBON_MASS_KG = 1.9926e-26  # m_s = m_carbon
CARBON_BOND_M = 1.315e-10  # l_s: Brenner's R_e in metres
TB_WELL_J = 1.0134e-18  # e_s

# Table 4: eq. 14 amplification constant epsilon
TB_EPSILON = 1.9926e-29
TB_GAIN = TB_EPSILON / CARBON_MASS_KG  # epsilon / m_carbon = 1e-3 (the unit is a reading, see params)

BRENNER_RE_ANGSTROM = 1.315  # R_e of Brenner's carbon set II, in angstrom


def rate_from_normalised(value: float) -> float:
    """A coefficient in units of 1/t_e (gain, damping) -> 1/s."""
    return value * EARTH_RATE_RADPS


def stiffness_from_normalised(value: float) -> float:
    """A coefficient in units of 1/t_e^2 (well amplitude alpha) -> 1/s^2."""
    return value * EARTH_RATE_RADPS**2


def area_from_normalised(value: float) -> float:
    """A squared length in units of l_e^2 (well range k) -> m^2."""
    return value * EARTH_RADIUS_M**2
