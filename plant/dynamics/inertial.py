"""Absolute orbits of N craft in ECI: two-body + J2 + drag, per-craft mass, area and drag coefficient.

Frame: ECI (Earth-centred inertial, z along the Earth's rotation axis, as absolute_j2.py; no
precession/nutation). State per craft (r [m], v [m/s]).

    r'' = -mu r/|r|^3 + a_J2(r) + a_D(r, v) + a_cmd
a_J2 (Vallado 4th ed. eq. 8-30) and a_D = -1/2 rho(h) B |v_rel| v_rel (eq. 8-29), B = C_D A / m
[m^2/kg] per craft, v_rel = v - omega_E x r, rho exponential (absolute_j2.drag_accel, constants.py).
The command a_cmd is held constant over the step, either in ECI (`thrust_frame="eci"`) or in each
craft's own rotating LVLH (`"lvlh"`, as absolute_j2.py); a force command is divided by the craft's
(constant) mass. Integration: fixed-step DOP853 (rk_tableau.rk_step, order 8) with sub-steps of at
most `max_step_s`.

`relative_lvlh(chief)` gives every craft relative to a chosen chief, in the chief's rotating LVLH
(frames.eci_to_lvlh, with the chief's natural acceleration for the frame's out-of-plane rotation).
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.plant.dynamics.absolute_j2 import drag_accel, gravity_j2_accel
from swarmhil.plant.dynamics.constants import ATMOSPHERE_H0_M, ATMOSPHERE_RHO0_KGPM3, ATMOSPHERE_SCALE_HEIGHT_M
from swarmhil.plant.dynamics.frames import argument_of_latitude, eci_to_lvlh, lvlh_vector_to_eci
from swarmhil.plant.dynamics.limits import force_to_accel
from swarmhil.plant.dynamics.rk_tableau import rk_step
from swarmhil.plant.dynamics.step_clock import StepClock

THRUST_FRAMES = ("eci", "lvlh")


def _per_craft(value: float | np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape[0] != n):
        raise ValueError(f"{name} must be a scalar or one value per craft ({n},), got shape {arr.shape}")
    arr = np.broadcast_to(arr, (n,)).copy()
    if np.any(~np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return arr


class InertialPropagator:
    """N craft in ECI under two-body + J2 (+ drag), each with its own mass_kg, area_m2 and cd."""

    frame = "eci"

    def __init__(
        self,
        *,
        r_eci_m: np.ndarray,
        v_eci_mps: np.ndarray,
        mass_kg: float | np.ndarray,
        area_m2: float | np.ndarray = 0.0,
        cd: float | np.ndarray = 2.2,
        j2: bool = True,
        drag: bool = True,
        thrust_frame: str = "eci",
        reference_index: int = 0,
        max_step_s: float = 30.0,
        rho0_kgpm3: float = ATMOSPHERE_RHO0_KGPM3,
        h0_m: float = ATMOSPHERE_H0_M,
        scale_height_m: float = ATMOSPHERE_SCALE_HEIGHT_M,
        rotating_atmosphere: bool = True,
    ) -> None:
        r = np.array(r_eci_m, dtype=float, ndmin=2)
        v = np.array(v_eci_mps, dtype=float, ndmin=2)
        if r.ndim != 2 or r.shape[1] != 3 or v.shape != r.shape:
            raise ValueError(f"r_eci_m and v_eci_mps must both be (N, 3), got {r.shape} and {v.shape}")
        n = r.shape[0]
        if thrust_frame not in THRUST_FRAMES:
            raise ValueError(f"thrust_frame must be one of {THRUST_FRAMES}, got {thrust_frame!r}")
        if not 0 <= reference_index < n:
            raise ValueError(f"reference_index must be in [0, {n}), got {reference_index}")
        if not max_step_s > 0.0:
            raise ValueError(f"max_step_s must be > 0, got {max_step_s!r}")
        self.mass_kg = _per_craft(mass_kg, n, "mass_kg")
        if np.any(self.mass_kg == 0.0):
            raise ValueError(f"mass_kg must be > 0, got {mass_kg!r}")
        self.area_m2 = _per_craft(area_m2, n, "area_m2")
        self.cd = _per_craft(cd, n, "cd")
        self.j2 = bool(j2)
        self.drag = bool(drag) and bool(np.any(self.area_m2 * self.cd > 0.0))
        self.thrust_frame = thrust_frame
        self.reference_index = int(reference_index)
        self.max_step_s = float(max_step_s)
        self._atmosphere = {
            "rho0_kgpm3": float(rho0_kgpm3), "h0_m": float(h0_m), "scale_height_m": float(scale_height_m),
            "rotating_atmosphere": bool(rotating_atmosphere),
        }
        self._y = np.hstack((r, v))
        self._accel_cmd = np.zeros((n, 3))
        self._thrusting = False
        self._clock = StepClock()

    # -------------------------------------------------------------------------------- physics

    @property
    def n_craft(self) -> int:
        return self._y.shape[0]

    @property
    def ballistic_coefficient_m2pkg(self) -> np.ndarray:
        """B = C_D A / m per craft [m^2/kg]."""
        return self.cd * self.area_m2 / self.mass_kg

    def natural_accel(self, r_m: np.ndarray, v_mps: np.ndarray, index: slice | np.ndarray = slice(None)) -> np.ndarray:
        """Gravity (+ J2) (+ drag) acceleration [m/s^2] of the craft `index` at ECI (r, v) (..., 3)."""
        accel = gravity_j2_accel(r_m, self.j2)
        if self.drag:
            accel = accel + drag_accel(r_m, v_mps, self.ballistic_coefficient_m2pkg[index], **self._atmosphere)
        return accel

    def _rhs(self, _t: float, y_flat: np.ndarray) -> np.ndarray:
        y = y_flat.reshape(-1, 6)
        r, v = y[:, :3], y[:, 3:]
        out = np.empty_like(y)
        out[:, :3] = v
        accel = self.natural_accel(r, v)
        if self._thrusting:
            if self.thrust_frame == "lvlh":
                accel += lvlh_vector_to_eci(r, v, self._accel_cmd)
            else:
                accel += self._accel_cmd
        out[:, 3:] = accel
        return out.ravel()

    # ----------------------------------------------------------------------------- protocol

    @property
    def t_s(self) -> float:
        return self._clock.t_s

    @property
    def u_rad(self) -> float:
        """Osculating argument of latitude of the reference craft (`reference_index`), in [0, 2 pi)."""
        i = self.reference_index
        return argument_of_latitude(self._y[i, :3], self._y[i, 3:])

    def step(self, accel_mps2: np.ndarray | None, dt_s: float) -> None:
        """Advance by dt_s with accel (N, 3) [m/s^2] in `thrust_frame` held constant (None: coast)."""
        n = self.n_craft
        accel = np.zeros((n, 3)) if accel_mps2 is None else np.asarray(accel_mps2, dtype=float)
        if accel.shape != (n, 3):
            raise ValueError(f"accel_mps2 must be ({n}, 3), got {accel.shape}")
        self._accel_cmd = accel
        self._thrusting = bool(np.any(accel != 0.0))
        n_sub = max(1, math.ceil(dt_s / self.max_step_s - 1e-12))
        h = dt_s / n_sub
        t0 = self.t_s
        y = self._y.ravel()
        for k in range(n_sub):
            y = rk_step(self._rhs, t0 + k * h, y, h)
        self._y = y.reshape(-1, 6)
        self._clock.advance(dt_s)

    def step_force(self, force_n: np.ndarray | None, dt_s: float) -> None:
        """`step` with a force command (N, 3) [N] in `thrust_frame`: a = F / m (constant mass)."""
        self.step(None if force_n is None else force_to_accel(force_n, self.mass_kg), dt_s)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """ECI positions (N, 3) [m] and velocities (N, 3) [m/s]."""
        return self._y[:, :3].copy(), self._y[:, 3:].copy()

    def relative_lvlh(self, chief_index: int | None = None,
                      chief_thrust_eci_mps2: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Every craft relative to the chief (default: `reference_index`), in the chief's rotating LVLH
        (positions (N, 3) [m], velocities (N, 3) [m/s]; the chief's own row is zero).
        `chief_thrust_eci_mps2`: the chief's thrust (ECI) now, added to its natural acceleration in the
        frame rate (a chief thrusting out of plane turns its LVLH about the radial axis)."""
        c = self.reference_index if chief_index is None else int(chief_index)
        if not 0 <= c < self.n_craft:
            raise ValueError(f"chief_index must be in [0, {self.n_craft}), got {chief_index}")
        r_c, v_c = self._y[c, :3], self._y[c, 3:]
        a_c = self.natural_accel(self._y[c : c + 1, :3], self._y[c : c + 1, 3:], slice(c, c + 1))[0]
        if chief_thrust_eci_mps2 is not None:
            a_c = a_c + np.asarray(chief_thrust_eci_mps2, dtype=float)
        return eci_to_lvlh(r_c, v_c, self._y[:, :3], self._y[:, 3:], a_c)
