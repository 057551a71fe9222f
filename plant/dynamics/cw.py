"""Clohessy-Wiltshire (Hill) relative motion about a circular reference orbit, exact discrete step.

Frame: LVLH of the reference (frames.py), x radial, y along-track, z cross-track; state
s = (x, y, z, vx, vy, vz) [m, m/s]. Any radius (LEO, GEO): n = sqrt(mu / a^3).

Equations (Clohessy & Wiltshire 1960; Vallado 4th ed. eq. 6-66; Schaub & Junkins eq. 14.43),
with a constant command acceleration (ax, ay, az) over the step:
    x'' = 3 n^2 x + 2 n y' + ax,    y'' = -2 n x' + ay,    z'' = -n^2 z + az,
i.e. s' = A s + B a with B = [0; I3]. Exact step (zero-order hold on a):
    s(t + dt) = Phi(dt) s(t) + Gamma(dt) a,   Gamma(dt) = int_0^dt Phi(dt - s) B ds = int_0^dt Phi(tau) B dtau.
Phi is the closed-form HCW state transition matrix (Vallado eq. 6-68); Gamma is its integral,
derived here column by column (theta = n dt, c = cos theta, s = sin theta):
    position rows:  [(1-c)/n^2,         2 (theta - s)/n^2,             0        ]
                    [-2 (theta - s)/n^2, 4 (1-c)/n^2 - 3/2 dt^2,        0        ]
                    [0,                  0,                             (1-c)/n^2]
    velocity rows:  [s/n,      2 (1-c)/n,       0  ]
                    [-2 (1-c)/n, 4 s/n - 3 dt,  0  ]
                    [0,        0,               s/n]
(1 - c) is written 2 sin^2(theta/2) and theta - sin theta by its series for small theta, so a 1 s
step at GEO (theta ~ 7e-5) loses no digits to cancellation.
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.plant.dynamics.constants import MU_EARTH_M3PS2
from swarmhil.plant.dynamics.step_clock import StepClock


def mean_motion(a_m: float, mu_m3ps2: float = MU_EARTH_M3PS2) -> float:
    """n = sqrt(mu / a^3) [rad/s] of the circular reference orbit of radius a_m."""
    if not a_m > 0.0:
        raise ValueError(f"a_m must be > 0, got {a_m!r}")
    return math.sqrt(mu_m3ps2 / a_m**3)


def _one_minus_cos(theta: float) -> float:
    """1 - cos theta = 2 sin^2(theta / 2), without cancellation."""
    h = math.sin(0.5 * theta)
    return 2.0 * h * h


def _theta_minus_sin(theta: float) -> float:
    """theta - sin theta; below |theta| = 0.5 its Taylor series sum_k (-1)^k theta^(2k+3)/(2k+3)!, k = 0..7
    (the first omitted term is < 1e-18 of the sum), otherwise directly."""
    if abs(theta) >= 0.5:
        return theta - math.sin(theta)
    t2 = theta * theta
    total = 0.0
    for k in range(7, -1, -1):  # Horner in theta^2
        total = 1.0 / math.factorial(2 * k + 3) - t2 * total
    return total * theta * t2


def transition_matrix(n_radps: float, dt_s: float) -> np.ndarray:
    """Phi(dt), (6, 6), the closed-form HCW state transition matrix (Vallado eq. 6-68), state (x,y,z,vx,vy,vz)."""
    n = n_radps
    th = n * dt_s
    c, s = math.cos(th), math.sin(th)
    omc = _one_minus_cos(th)
    tms = _theta_minus_sin(th)
    return np.array(
        [
            [4.0 - 3.0 * c, 0.0, 0.0, s / n, 2.0 * omc / n, 0.0],
            [-6.0 * tms, 1.0, 0.0, -2.0 * omc / n, (4.0 * s - 3.0 * th) / n, 0.0],
            [0.0, 0.0, c, 0.0, 0.0, s / n],
            [3.0 * n * s, 0.0, 0.0, c, 2.0 * s, 0.0],
            [-6.0 * n * omc, 0.0, 0.0, -2.0 * s, 4.0 * c - 3.0, 0.0],
            [0.0, 0.0, -n * s, 0.0, 0.0, c],
        ]
    )


def zoh_input_matrix(n_radps: float, dt_s: float) -> np.ndarray:
    """Gamma(dt) = int_0^dt Phi(tau) B dtau, (6, 3): response to a constant LVLH acceleration (module docstring)."""
    n = n_radps
    th = n * dt_s
    s = math.sin(th)
    omc = _one_minus_cos(th)
    tms = _theta_minus_sin(th)
    n2 = n * n
    return np.array(
        [
            [omc / n2, 2.0 * tms / n2, 0.0],
            [-2.0 * tms / n2, 4.0 * omc / n2 - 1.5 * dt_s * dt_s, 0.0],
            [0.0, 0.0, omc / n2],
            [s / n, 2.0 * omc / n, 0.0],
            [-2.0 * omc / n, 4.0 * s / n - 3.0 * dt_s, 0.0],
            [0.0, 0.0, s / n],
        ]
    )


def state_matrix(n_radps: float) -> np.ndarray:
    """A, (6, 6): s' = A s + B a for the HCW equations (module docstring)."""
    n = n_radps
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0] = 3.0 * n * n
    a[3, 4] = 2.0 * n
    a[4, 3] = -2.0 * n
    a[5, 2] = -n * n
    return a


def propagate_cw(
    pos_m: np.ndarray, vel_mps: np.ndarray, accel_mps2: np.ndarray | None, n_radps: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Exact step of every craft: s(dt) = Phi(dt) s + Gamma(dt) a, a held constant. Shapes (N, 3)."""
    state = np.hstack((np.asarray(pos_m, dtype=float), np.asarray(vel_mps, dtype=float)))
    out = state @ transition_matrix(n_radps, dt_s).T
    if accel_mps2 is not None:
        out += np.asarray(accel_mps2, dtype=float) @ zoh_input_matrix(n_radps, dt_s).T
    return out[:, :3], out[:, 3:]


class CwPropagator:
    """N craft on the HCW equations about a circular reference of radius a_m (frame: reference LVLH).

    `step(accel_mps2 (N, 3) LVLH, dt_s)`: exact zero-order-hold step (`propagate_cw`); Phi and Gamma
    are cached per distinct dt. Time runs as t = t_base + k dt (k steps of the same dt), so a long
    run at constant step has no accumulated round-off in t. `u_rad` = u0 + n t, not wrapped.
    """

    frame = "lvlh"

    def __init__(
        self, a_m: float, pos_m: np.ndarray, vel_mps: np.ndarray, u0_rad: float = 0.0,
        mu_m3ps2: float = MU_EARTH_M3PS2,
    ) -> None:
        pos = np.array(pos_m, dtype=float, ndmin=2)
        vel = np.array(vel_mps, dtype=float, ndmin=2)
        if pos.ndim != 2 or pos.shape[1] != 3 or vel.shape != pos.shape:
            raise ValueError(f"pos_m and vel_mps must both be (N, 3), got {pos.shape} and {vel.shape}")
        self.a_m = float(a_m)
        self.n_radps = mean_motion(self.a_m, mu_m3ps2)
        self.u0_rad = float(u0_rad)
        self._state = np.hstack((pos, vel))
        self._clock = StepClock()
        self._cache_dt: float | None = None
        self._phi_t = np.eye(6)
        self._gamma_t = np.zeros((3, 6))

    @property
    def n_craft(self) -> int:
        return self._state.shape[0]

    @property
    def t_s(self) -> float:
        return self._clock.t_s

    @property
    def u_rad(self) -> float:
        """Reference argument of latitude u0 + n t [rad] (mean = true on the circular reference), unwrapped."""
        return self.u0_rad + self.n_radps * self.t_s

    def step(self, accel_mps2: np.ndarray | None, dt_s: float) -> None:
        """Advance by dt_s with each craft's LVLH acceleration (N, 3) [m/s^2] held constant."""
        if dt_s != self._cache_dt:
            self._phi_t = transition_matrix(self.n_radps, dt_s).T
            self._gamma_t = zoh_input_matrix(self.n_radps, dt_s).T
            self._cache_dt = dt_s
        out = self._state @ self._phi_t
        if accel_mps2 is not None:
            accel = np.asarray(accel_mps2, dtype=float)
            if accel.shape != (self.n_craft, 3):
                raise ValueError(f"accel_mps2 must be ({self.n_craft}, 3), got {accel.shape}")
            out += accel @ self._gamma_t
        self._state = out
        self._clock.advance(dt_s)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) [m] and velocities (N, 3) [m/s] in the reference LVLH frame."""
        return self._state[:, :3].copy(), self._state[:, 3:].copy()
