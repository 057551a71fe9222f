"""The plant's truth: translational state of every spacecraft, actuator limits, delta-v accounting.

The dynamics are a propagator chosen by name (`fidelity`, plant/dynamics/propagator.py) among
those working in the reference LVLH frame: `linear` propagates the ROE exactly with the Keplerian
model of paper 002 (plant/dynamics/roe_linear.py); `j2` integrates two-body + J2 (+ optional drag)
absolute orbits and converts them to the reference LVLH every step (plant/dynamics/absolute_j2.py);
`cw` is Clohessy-Wiltshire about the circular reference (plant/dynamics/cw.py). The plant flies
it for the fidelities it registers (plant/worlds.py): `linear` and `j2`, paper 002's truth models.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from swarmhil.plant.config import PlantConfig
from swarmhil.plant.dynamics import roe_linear
from swarmhil.plant.dynamics.limits import limit_per_axis
from swarmhil.plant.dynamics.propagator import Propagator, make_propagator
from swarmhil.plant.worlds import register_world


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
        # issue 27: (applied accelerations, step) -> applied accelerations (plant/faults.py ActuationFaults)
        self.actuation_faults: Callable[[np.ndarray, int], np.ndarray] | None = None
        init = {"a_m": self.a_m, "inc_rad": inc_rad, "raan_rad": raan_rad, "u0_rad": self.u0_rad,
                "roe_m": np.array(roe_m, dtype=float).reshape(n, 6)}
        if drag is not None:
            init["drag"] = drag
        self.propagator: Propagator = make_propagator(fidelity, **init)
        if self.propagator.frame != "lvlh":
            raise ValueError(f"plant fidelity {fidelity!r} is not a relative (LVLH) propagator")

    @classmethod
    def of(cls, config: PlantConfig) -> "World":
        """The world of a plant configuration (plant/config.py), as PlantNode has always built it."""
        o = config.orbit
        return cls(list(config.ids), config.roe_m, a_m=o.semi_major_axis_m, inc_rad=o.inclination_rad,
                   raan_rad=o.raan_rad, u0_rad=o.u0_rad, fidelity=config.fidelity, drag=config.drag,
                   max_accel_mps2=config.max_accel_mps2)

    @property
    def u_rad(self) -> float:
        """Reference argument of latitude (mean, for linear/cw; osculating for j2)."""
        return self.propagator.u_rad

    def lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,3) positions and velocities in the reference LVLH frame."""
        return self.propagator.state()

    def roe_m(self, lvlh: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """(N,6) ROE in metres (for models without ROE state: the linear map of the LVLH state,
        an osculating approximation for j2; `lvlh`: this step's `lvlh()`, when the caller has it)."""
        own = getattr(self.propagator, "roe_m", None)
        if own is not None:
            return own()
        pos, vel = self.propagator.state() if lvlh is None else lvlh
        return roe_linear.lvlh_to_roe(pos, vel, self.u_rad, self.n_radps)

    def limit(self, accel_mps2: np.ndarray, all_alive: bool = False) -> np.ndarray:
        """Actuator model: each axis saturates at +-max_accel (three thruster pairs); dead spacecraft
        coast (`all_alive`: the caller knows none is dead, no rows to zero)."""
        a = limit_per_axis(accel_mps2, self.max_accel_mps2)
        if not all_alive:
            a[~self.alive] = 0.0
        return a

    def step(self, accel_mps2: np.ndarray, dt_s: float, all_alive: bool = False) -> None:
        """Advance by dt with each command held constant over the step; delta-v += |a| dt
        (`all_alive`: as for `limit`)."""
        c0 = time.perf_counter()
        a = self.limit(accel_mps2, all_alive)
        if self.actuation_faults is not None:
            a = self.actuation_faults(a, self.steps_done)
        self.last_accel_mps2 = a
        self.delta_v_mps += np.sqrt(np.add.reduce(a * a, axis=1)) * dt_s  # np.linalg.norm(a, axis=1), its arithmetic
        self.propagator.step(a, dt_s)
        self.steps_done += 1
        self.t_s = self.steps_done * dt_s
        self.wall_s += time.perf_counter() - c0


register_world("linear", "j2")(World.of)  # paper 002's ROE plants (bit-identical since issue 2)
