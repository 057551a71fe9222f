"""Nonlinear absolute dynamics in ECI: two-body + J2 (+ optional exponential-atmosphere drag).

The plant integrates the reference orbit and every spacecraft as one ECI state vector with a
fixed-step 8th-order Runge-Kutta (the Dormand-Prince 8(5,3) tableau of DOP853, Hairer, Norsett &
Wanner, Solving ODEs I, sec. II.10, without step control; `rk_tableau`), and gives relative states in the
reference's rotating LVLH frame (`frames.eci_to_lvlh`).

Forces (Vallado, 4th ed.): point mass -mu r/|r|^3; J2 (eq. 8-30)
    a_J2 = -3/2 J2 mu R^2 / r^5 (x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2));
drag (eq. 8-29) a_D = -1/2 rho(h) B |v_rel| v_rel, B = C_D A / m, v_rel = v - omega_E x r, with
rho(h) = rho0 exp(-(h - h0)/H) over a spherical Earth (h = |r| - R_E).

Elements: classical (a, e, i, raan, argp, nu) for `kepler_to_eci`; quasi-nonsingular
(a, u, ex, ey, i, raan) with u = argp + M the mean argument of latitude and (ex, ey) =
e (cos argp, sin argp) for the ROE maps (D'Amico 2010, sec. 2.1; NOTES-002).
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.plant.dynamics.constants import (
    ATMOSPHERE_H0_M,
    ATMOSPHERE_RHO0_KGPM3,
    ATMOSPHERE_SCALE_HEIGHT_M,
    J2,
    MU_EARTH_M3PS2,
    OMEGA_EARTH_RADPS,
    R_EARTH_M,
)
from swarmhil.plant.dynamics.frames import argument_of_latitude, eci_to_lvlh, lvlh_vector_to_eci
from swarmhil.plant.dynamics.rk_tableau import rk_step

__all__ = [
    "AbsoluteJ2Plant",
    "eci_to_lvlh",
    "kepler_to_eci",
    "qns_to_eci",
    "roe_to_absolute_elements",
    "gravity_j2_accel",
    "drag_accel",
    "rk8_step",
]

_J2_COEFF = -1.5 * J2 * MU_EARTH_M3PS2 * R_EARTH_M**2


# ----------------------------------------------------------------------------------- elements


def kepler_to_eci(
    a: float | np.ndarray,
    e: float | np.ndarray,
    i: float | np.ndarray,
    raan: float | np.ndarray,
    argp: float | np.ndarray,
    nu: float | np.ndarray,
    mu: float = MU_EARTH_M3PS2,
) -> tuple[np.ndarray, np.ndarray]:
    """Classical elements (a [m], e, i, raan, argp, nu [rad]) -> ECI r [m], v [m/s], shape (..., 3).

    Perifocal position/velocity rotated by R3(-raan) R1(-i) R3(-argp) (Vallado alg. 10, COE2RV).
    Arrays broadcast.
    """
    a, e, i, raan, argp, nu = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (a, e, i, raan, argp, nu))
    )
    p = a * (1.0 - e**2)
    r_pf = p / (1.0 + e * np.cos(nu))
    sqrt_mu_p = np.sqrt(mu / p)
    # In-plane unit vectors P (periapsis) and Q (90 deg ahead) in ECI.
    co, so = np.cos(raan), np.sin(raan)
    cw, sw = np.cos(argp), np.sin(argp)
    ci, si = np.cos(i), np.sin(i)
    p_hat = np.stack((co * cw - so * sw * ci, so * cw + co * sw * ci, sw * si), axis=-1)
    q_hat = np.stack((-co * sw - so * cw * ci, -so * sw + co * cw * ci, cw * si), axis=-1)
    cn, sn = np.cos(nu)[..., None], np.sin(nu)[..., None]
    r = r_pf[..., None] * (cn * p_hat + sn * q_hat)
    v = sqrt_mu_p[..., None] * (-sn * p_hat + (e[..., None] + cn) * q_hat)
    return r, v


def _true_from_mean_anomaly(mean_anomaly: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Solve Kepler's equation E - e sin E = M (Newton, to machine precision) and return nu."""
    ecc_anomaly = mean_anomaly + e * np.sin(mean_anomaly)
    for _ in range(50):
        delta = (ecc_anomaly - e * np.sin(ecc_anomaly) - mean_anomaly) / (1.0 - e * np.cos(ecc_anomaly))
        ecc_anomaly = ecc_anomaly - delta
        if np.all(np.abs(delta) < 1e-15):
            break
    half = 0.5 * ecc_anomaly
    return 2.0 * np.arctan2(np.sqrt(1.0 + e) * np.sin(half), np.sqrt(1.0 - e) * np.cos(half))


def qns_to_eci(elements: np.ndarray, mu: float = MU_EARTH_M3PS2) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-nonsingular elements (..., 6) = (a, u, ex, ey, i, raan), u mean -> ECI r, v (..., 3).

    argp = atan2(ey, ex) (0 when e = 0), M = u - argp, nu from Kepler's equation.
    """
    el = np.asarray(elements, dtype=float)
    a, u, ex, ey, inc, raan = (el[..., k] for k in range(6))
    e = np.hypot(ex, ey)
    argp = np.arctan2(ey, ex)
    nu = _true_from_mean_anomaly(u - argp, e)
    return kepler_to_eci(a, e, inc, raan, argp, nu, mu)


def roe_to_absolute_elements(ref_elements: np.ndarray, roe_m: np.ndarray) -> np.ndarray:
    """Deputy quasi-nonsingular elements (N, 6) from the reference's (6,) and ROE in metres (N, 6).

    Inverts D'Amico's definitions (NOTES-002) exactly, elements (a, u, ex, ey, i, raan):
      a_d = a (1 + da);  i_d = i + dix;  raan_d = raan + diy / sin i;
      u_d = u + dl - (raan_d - raan) cos i;  ex_d = ex + dex;  ey_d = ey + dey.
    The ROE are treated as OSCULATING (built from osculating elements of both orbits), not mean:
    under J2 the osculating/mean difference appears as short-period relative motion and, for
    cross-track (di) separations, a differential mean semi-major axis, i.e. an along-track drift.
    """
    ref = np.asarray(ref_elements, dtype=float)
    roe = np.asarray(roe_m, dtype=float)
    a, u, ex, ey, inc, raan = ref
    d = roe / a
    if abs(math.sin(inc)) < 1e-9 and np.any(d[..., 5] != 0.0):
        raise ValueError(f"diy is undefined for an equatorial reference (inc = {inc} rad)")
    d_raan = d[..., 5] / math.sin(inc) if abs(math.sin(inc)) >= 1e-9 else 0.0 * d[..., 5]
    return np.stack(
        (
            a * (1.0 + d[..., 0]),
            u + d[..., 1] - d_raan * math.cos(inc),
            ex + d[..., 2],
            ey + d[..., 3],
            inc + d[..., 4],
            raan + d_raan,
        ),
        axis=-1,
    )


# -------------------------------------------------------------------------------------- forces


def gravity_j2_accel(r_m: np.ndarray, j2: bool = True) -> np.ndarray:
    """Point-mass gravity plus (if j2) the J2 zonal term (Vallado eq. 8-30), r (..., 3) -> (..., 3)."""
    inv_r2 = 1.0 / np.einsum("...i,...i->...", r_m, r_m)[..., None]
    inv_r = np.sqrt(inv_r2)
    mu_r3 = MU_EARTH_M3PS2 * inv_r2 * inv_r
    if not j2:
        return -mu_r3 * r_m
    z = r_m[..., 2:3]
    k = _J2_COEFF * (inv_r2 * inv_r2 * inv_r)  # -3/2 J2 mu R^2 / r^5
    accel = (k * (1.0 - 5.0 * z * z * inv_r2) - mu_r3) * r_m
    accel[..., 2:3] += 2.0 * k * z
    return accel


def drag_accel(
    r_m: np.ndarray,
    v_mps: np.ndarray,
    bc_m2pkg: np.ndarray,
    rho0_kgpm3: float = ATMOSPHERE_RHO0_KGPM3,
    h0_m: float = ATMOSPHERE_H0_M,
    scale_height_m: float = ATMOSPHERE_SCALE_HEIGHT_M,
    rotating_atmosphere: bool = True,
) -> np.ndarray:
    """Drag a = -1/2 rho(h) B |v_rel| v_rel (Vallado eq. 8-29), B = C_D A/m [m^2/kg] per body (...,)."""
    v_rel = v_mps
    if rotating_atmosphere:
        omega_cross_r = np.stack((-r_m[..., 1], r_m[..., 0], np.zeros_like(r_m[..., 0])), axis=-1)
        v_rel = v_mps - OMEGA_EARTH_RADPS * omega_cross_r
    h = np.linalg.norm(r_m, axis=-1) - R_EARTH_M
    rho = rho0_kgpm3 * np.exp(-(h - h0_m) / scale_height_m)
    speed = np.linalg.norm(v_rel, axis=-1)
    return (-0.5 * rho * np.asarray(bc_m2pkg) * speed)[..., None] * v_rel


# ---------------------------------------------------------------------------------- integrator


def rk8_step(f, t: float, y: np.ndarray, h: float) -> np.ndarray:
    """One fixed step of the 8th-order Dormand-Prince Runge-Kutta (DOP853 tableau, `rk_tableau`) of y' = f(t, y)."""
    return rk_step(f, t, y, h)


# --------------------------------------------------------------------------------------- plant

_DRAG_KEYS = {"bc_m2pkg", "bc_ref_m2pkg", "rho0_kgpm3", "h0_m", "scale_height_m", "rotating_atmosphere"}


class AbsoluteJ2Plant:
    """Reference orbit and N spacecraft integrated in ECI (two-body + J2 [+ drag]).

    - The reference starts circular (osculating) at (a_m, inc_rad, raan_rad, u0_rad); spacecraft
      start at the reference's elements offset by their ROE (`roe_to_absolute_elements`, OSCULATING).
    - `step(accel_lvlh_mps2, dt_s)`: each spacecraft's command is expressed in its OWN LVLH frame
      (from its own r, v) and held constant in that rotating frame over the step (zero-order hold in
      LVLH, as in `roe_linear.propagate_roe`); the reference is never thrusted.
    - `drag`: None, or a dict with `bc_m2pkg` (C_D A/m, float or (N,)), optional `bc_ref_m2pkg`
      (default: mean of bc_m2pkg, so a uniform swarm has no differential drag against the
      reference), `rho0_kgpm3`, `h0_m`, `scale_height_m`, `rotating_atmosphere` (default True).
    - Integration: fixed-step RK8 with steps of at most `max_step_s` (default 30 s).
    """

    def __init__(
        self,
        a_m: float,
        inc_rad: float,
        raan_rad: float,
        u0_rad: float,
        roe_m: np.ndarray,
        j2: bool = True,
        drag: dict | None = None,
        max_step_s: float = 30.0,
    ) -> None:
        roe = np.array(roe_m, dtype=float, ndmin=2)
        if roe.ndim != 2 or roe.shape[1] != 6:
            raise ValueError(f"roe_m must be (N, 6), got shape {roe.shape}")
        self.n_sc = roe.shape[0]
        self.j2 = bool(j2)
        self.max_step_s = float(max_step_s)
        self.t_s = 0.0
        ref_el = np.array([a_m, u0_rad, 0.0, 0.0, inc_rad, raan_rad], dtype=float)
        elements = np.vstack((ref_el, roe_to_absolute_elements(ref_el, roe)))
        r, v = qns_to_eci(elements)
        self._y = np.hstack((r, v))  # (N + 1, 6), row 0 = reference
        self._drag = self._parse_drag(drag)
        self._accel_lvlh = np.zeros((self.n_sc, 3))
        self._thrusting = False

    def _parse_drag(self, drag: dict | None) -> dict | None:
        if drag is None:
            return None
        unknown = set(drag) - _DRAG_KEYS
        if unknown or "bc_m2pkg" not in drag:
            raise ValueError(f"drag needs 'bc_m2pkg' and only keys {sorted(_DRAG_KEYS)}, got {sorted(drag)}")
        bc = np.broadcast_to(np.asarray(drag["bc_m2pkg"], dtype=float), (self.n_sc,))
        bc_ref = float(drag.get("bc_ref_m2pkg", bc.mean()))
        return {
            "bc_m2pkg": np.concatenate(([bc_ref], bc)),
            "rho0_kgpm3": float(drag.get("rho0_kgpm3", ATMOSPHERE_RHO0_KGPM3)),
            "h0_m": float(drag.get("h0_m", ATMOSPHERE_H0_M)),
            "scale_height_m": float(drag.get("scale_height_m", ATMOSPHERE_SCALE_HEIGHT_M)),
            "rotating_atmosphere": bool(drag.get("rotating_atmosphere", True)),
        }

    def _natural_accel(self, r: np.ndarray, v: np.ndarray) -> np.ndarray:
        accel = gravity_j2_accel(r, self.j2)
        if self._drag is not None:
            accel = accel + drag_accel(r, v, **self._drag)
        return accel

    def _rhs(self, _t: float, y_flat: np.ndarray) -> np.ndarray:
        y = y_flat.reshape(-1, 6)
        r, v = y[:, :3], y[:, 3:]
        out = np.empty_like(y)
        out[:, :3] = v
        accel = self._natural_accel(r, v)
        if self._thrusting:
            accel[1:] += lvlh_vector_to_eci(r[1:], v[1:], self._accel_lvlh)
        out[:, 3:] = accel
        return out.ravel()

    def step(self, accel_lvlh_mps2: np.ndarray | None, dt_s: float) -> None:
        """Advance by dt_s with each spacecraft's LVLH acceleration (N, 3) held in its own LVLH frame."""
        if accel_lvlh_mps2 is None:
            accel = np.zeros((self.n_sc, 3))
        else:
            accel = np.asarray(accel_lvlh_mps2, dtype=float)
        if accel.shape != (self.n_sc, 3):
            raise ValueError(f"accel_lvlh_mps2 must be ({self.n_sc}, 3), got {accel.shape}")
        self._accel_lvlh = accel
        self._thrusting = bool(np.any(accel != 0.0))
        n_sub = max(1, math.ceil(dt_s / self.max_step_s - 1e-12))
        h = dt_s / n_sub
        y = self._y.ravel()
        for k in range(n_sub):
            y = rk8_step(self._rhs, self.t_s + k * h, y, h)
        self._y = y.reshape(-1, 6)
        self.t_s += dt_s

    def reference_eci(self) -> tuple[np.ndarray, np.ndarray]:
        """ECI position (3,) [m] and velocity (3,) [m/s] of the reference."""
        return self._y[0, :3].copy(), self._y[0, 3:].copy()

    def spacecraft_eci(self) -> tuple[np.ndarray, np.ndarray]:
        """ECI positions (N, 3) [m] and velocities (N, 3) [m/s] of the spacecraft."""
        return self._y[1:, :3].copy(), self._y[1:, 3:].copy()

    def reference_u(self) -> float:
        """Osculating (true) argument of latitude of the reference, in [0, 2 pi).

        Angle from the ascending node to r in the orbit plane; it differs from the mean argument of
        latitude of the linear model by J2 short-period terms (~1e-3 rad at 500 km).
        """
        return argument_of_latitude(self._y[0, :3], self._y[0, 3:])

    def relative_lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) [m] and velocities (N, 3) [m/s] relative to the reference, in its rotating
        LVLH frame (transport theorem with the frame's full angular velocity, incl. the J2 part)."""
        r_ref, v_ref = self._y[0, :3], self._y[0, 3:]
        a_ref = self._natural_accel(self._y[:1, :3], self._y[:1, 3:])[0]
        return eci_to_lvlh(r_ref, v_ref, self._y[1:, :3], self._y[1:, 3:], a_ref)
