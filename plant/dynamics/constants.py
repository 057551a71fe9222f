"""Earth constants shared by every plant dynamics model (the one place they are spelled).

Values: EGM2008 / WGS-84 GM and equatorial radius, EGM2008 unnormalised J2 (Vallado, 4th ed.,
App. D); Earth rotation rate IERS nominal. Exponential-atmosphere defaults: Vallado Table 8-4,
500 km band.
"""
from __future__ import annotations

MU_EARTH_M3PS2: float = 3.986004418e14
R_EARTH_M: float = 6378137.0
J2: float = 1.08262668e-3
OMEGA_EARTH_RADPS: float = 7.292115e-5

# Exponential atmosphere rho = rho0 exp(-(h - h0)/H), Vallado Table 8-4 (500-600 km band).
ATMOSPHERE_H0_M: float = 500.0e3
ATMOSPHERE_RHO0_KGPM3: float = 6.967e-13
ATMOSPHERE_SCALE_HEIGHT_M: float = 63.822e3
