"""The plant's truth: translational state of every spacecraft, actuator limits, delta-v accounting.

Two fidelities (issue 2): `linear` propagates the ROE exactly with the Keplerian model of paper
002 (command held constant over the step, plant/dynamics/roe_linear.py); `j2` integrates two-body
+ J2 (+ optional drag) absolute orbits and converts them to the reference LVLH every step
(plant/dynamics/absolute_j2.py).
"""
from __future__ import annotations

import time

import numpy as np

from plant.dynamics import roe_linear


class World:
    def __init__(self, ids: list[str], roe_m: np.ndarray, *, a_m: float, inc_rad: float, raan_rad: float,
                 u0_rad: float, fidelity: str = "linear", drag: dict | None = None,
                 max_accel_mps2: float = 1e-3) -> None:
        self.ids = list(ids)
        self.index = {sid: i for i, sid in enumerate(self.ids)}
        self.a_m = float(a_m)
        self.n_radps = roe_linear.mean_motion(self.a_m)
        self.u0_rad = float(u0_rad)
        self.fidelity = fidelity
        self.max_accel_mps2 = float(max_accel_mps2)
        self.t_s = 0.0
        self.steps_done = 0
        self.wall_s = 0.0  # wall time spent propagating (for benchmarks)
        n = len(self.ids)
        self.alive = np.ones(n, dtype=bool)
        self.delta_v_mps = np.zeros(n)
        self.last_accel_mps2 = np.zeros((n, 3))
        if fidelity == "linear":
            self._roe = np.array(roe_m, dtype=float).reshape(n, 6)
            self._abs = None
        elif fidelity == "j2":
            from plant.dynamics.absolute_j2 import AbsoluteJ2Plant

            self._roe = None
            self._abs = AbsoluteJ2Plant(self.a_m, inc_rad, raan_rad, self.u0_rad, np.asarray(roe_m, float), j2=True, drag=drag)
        else:
            raise ValueError(f"unknown plant fidelity {fidelity!r}; known: linear, j2")

    @property
    def u_rad(self) -> float:
        """Reference argument of latitude (mean, for the linear model; osculating for j2)."""
        if self._abs is not None:
            return float(self._abs.reference_u())
        return self.u0_rad + self.n_radps * self.t_s

    def lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,3) positions and velocities in the reference LVLH frame."""
        if self._abs is not None:
            return self._abs.relative_lvlh()
        return roe_linear.roe_to_lvlh(self._roe, self.u_rad, self.n_radps)

    def roe_m(self) -> np.ndarray:
        """(N,6) ROE in metres (for j2: the linear map of the LVLH state, an osculating approximation)."""
        if self._roe is not None:
            return self._roe.copy()
        pos, vel = self._abs.relative_lvlh()
        return roe_linear.lvlh_to_roe(pos, vel, self.u_rad, self.n_radps)

    def limit(self, accel_mps2: np.ndarray) -> np.ndarray:
        """Actuator model: each axis saturates at +-max_accel (three thruster pairs); dead spacecraft coast."""
        a = np.clip(np.asarray(accel_mps2, float), -self.max_accel_mps2, self.max_accel_mps2)
        a[~self.alive] = 0.0
        return a

    def step(self, accel_mps2: np.ndarray, dt_s: float) -> None:
        """Advance by dt with each command held constant over the step; delta-v += |a| dt."""
        c0 = time.perf_counter()
        a = self.limit(accel_mps2)
        self.last_accel_mps2 = a
        self.delta_v_mps += np.linalg.norm(a, axis=1) * dt_s
        if self._abs is not None:
            self._abs.step(a, dt_s)
        else:
            self._roe = roe_linear.propagate_roe(self._roe, a, self.u_rad, self.n_radps, dt_s)
        self.steps_done += 1
        self.t_s = self.steps_done * dt_s
        self.wall_s += time.perf_counter() - c0
