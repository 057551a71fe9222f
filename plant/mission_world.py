"""The plant's truth for Cartesian scenarios (issue 11): spacecraft and bodies on the `cw` or
`inertial` propagator, per-craft actuator limits, rigid-body attitude, kinematic bodies.

Same interface as plant/world.py's `World` (which keeps the `linear` / `j2` ROE scenarios of paper
002 bit for bit), plus bodies and attitude:

- frame: every position, velocity and command is in the LVLH frame of the scenario's origin: the
  circular reference orbit of `[orbit]` (`[plant].frame_origin = "reference"`, default) or a
  spacecraft or propagated body (`frame_origin = "<id>"`; its LVLH rotates with it).
- `[plant].command_frame = "eci"` (inertial only): acceleration commands are in ECI axes and are
  applied as given (a mission whose flight software computes in inertial axes, paper 004); the
  Truth's `accel_cmd_mps2` (`last_accel_mps2`) is still in the scenario frame, rotated with the
  origin's LVLH at the start of the step. The reference orbit may be eccentric (`[orbit]
  eccentricity`, `argp_deg`; `u0_deg` is then argp + the true anomaly at t = 0).
- `cw`: Clohessy-Wiltshire about the circular reference (plant/dynamics/cw.py); spacecraft and
  propagated bodies are rows of one propagator.
- `inertial`: two-body + J2 + drag in ECI for every row (plant/dynamics/inertial.py), each with its
  own mass, area and drag coefficient; the reference orbit is one more (drag-free) row when it is the
  origin. Initial LVLH states map to ECI with the transport theorem (`lvlh_to_eci`).
- actuators: acceleration limit per craft, `per_axis` or by `norm` ([[spacecraft]] max_accel_mps2 or
  max_force_n / mass_kg); torque limit by norm where attitude is flown.
- attitude: craft with `inertia_kgm2` get Euler's equations (plant/dynamics/attitude.py) in an
  inertial frame aligned with the origin's LVLH at t = 0. The LVLH frame turns by n t from it
  (0.61 rad in paper 000's 550 s at 500 km): a sensor reporting attitude in the rotating frame must
  rotate it (missions/p000_capture/sense.py does).
- kinematic bodies: position p0 + v t, attitude q(t) = R(axis, w t) q0 (constant spin about a fixed
  axis of the scenario frame).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from swarmhil.plant.bodies import BodySpec, manoeuvre_accel
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.dynamics import roe_linear
from swarmhil.plant.dynamics.absolute_j2 import kepler_to_eci
from swarmhil.plant.dynamics.attitude import AttitudePropagator, quat_from_axis_angle, quat_multiply
from swarmhil.plant.dynamics.frames import cross, lvlh_angular_velocity, lvlh_basis, lvlh_vector_to_eci
from swarmhil.plant.dynamics.limits import limit_norm, limit_norm_rows, limit_per_axis, row_norm
from swarmhil.plant.dynamics.propagator import make_propagator
from swarmhil.plant.faults import BodyFault, BodyManoeuvre, manoeuvre_displacement, spin_segments
from swarmhil.plant.worlds import register_world


def lvlh_to_eci(r_ref_m: np.ndarray, v_ref_mps: np.ndarray, rho_m: np.ndarray,
                rho_dot_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of frames.eci_to_lvlh (two-body frame rate): r = r_ref + R^T rho,
    v = v_ref + R^T (rho_dot + omega x rho)."""
    rot = lvlh_basis(r_ref_m, v_ref_mps)
    omega = lvlh_angular_velocity(r_ref_m, v_ref_mps)
    rho = np.asarray(rho_m, float)
    r = np.asarray(r_ref_m, float) + rho @ rot
    v = np.asarray(v_ref_mps, float) + (np.asarray(rho_dot_mps, float) + cross(omega, rho)) @ rot
    return r, v


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, float)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, float)
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


@dataclass
class BodyTruth:
    """One non-agent body at the current step (scenario frame; q scalar-first, body -> frame)."""

    spec: BodySpec
    position_m: np.ndarray
    velocity_mps: np.ndarray
    attitude_q: np.ndarray
    angular_velocity_radps: np.ndarray


class MissionWorld:
    def __init__(self, sc: PlantConfig) -> None:
        """`sc`: the plant's configuration (plant/config.py)."""
        o = sc.orbit
        self.ids = list(sc.ids)
        self.index = {sid: i for i, sid in enumerate(self.ids)}
        self.specs = list(sc.spacecraft)
        self.bodies = list(sc.bodies)
        self.a_m = float(o.semi_major_axis_m)
        self.n_radps = roe_linear.mean_motion(self.a_m)
        self.u0_rad = float(o.u0_rad)
        self.fidelity = sc.fidelity
        self.t_s = 0.0
        self.steps_done = 0
        self.wall_s = 0.0
        n = len(self.ids)
        self.alive = np.ones(n, dtype=bool)
        self.delta_v_mps = np.zeros(n)
        self.last_accel_mps2 = np.zeros((n, 3))
        self.last_torque_nm = np.zeros((n, 3))
        # issue 27: (applied accelerations, step) -> applied accelerations (plant/faults.py ActuationFaults)
        self.actuation_faults: Callable[[np.ndarray, int], np.ndarray] | None = None
        # issue 27: {body id: body_manoeuvre / body_spin faults} (plant/faults.py body_faults)
        self.body_faults: dict[str, list[BodyFault]] = {}
        self._kinematic_at: tuple[tuple[float, int], list[BodyTruth]] | None = None  # ((t_s, faults), their truth)
        self.max_accel_mps2 = np.array([self._max_accel(s, sc) for s in self.specs])
        self.limit_mode = [s.limit or sc.actuator_limit for s in self.specs]
        self._plan_limits()
        self._rows_at = -1  # the step whose rows in the scenario frame (and u) are kept in _rows / _u
        self._rows: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 3)), np.zeros((0, 3)))
        self._u_at = -1
        self._u = 0.0
        # rows of the translational propagator: spacecraft, then propagated bodies
        self.prop_bodies = [b for b in self.bodies if b.motion.kind == "propagated"]
        self.kin_bodies = [b for b in self.bodies if b.motion.kind == "kinematic"]
        pos0, vel0 = [], []
        for s, roe in zip(self.specs, sc.roe_m):
            if s.position_m is not None:
                pos0.append(s.position_m)
                vel0.append(s.velocity_mps)
            else:
                p, v = roe_linear.roe_to_lvlh(np.asarray([roe], float), self.u0_rad, self.n_radps)
                pos0.append(p[0])
                vel0.append(v[0])
        for b in self.prop_bodies:
            pos0.append(b.motion.position_m)
            vel0.append(b.motion.velocity_mps)
        pos0, vel0 = np.asarray(pos0, float).reshape(-1, 3), np.asarray(vel0, float).reshape(-1, 3)
        origin = sc.plant_options.get("frame_origin", "reference")
        row_ids = self.ids + [b.id for b in self.prop_bodies]
        if origin != "reference" and origin not in row_ids:
            raise ValueError(f"[plant].frame_origin {origin!r} is not a spacecraft or propagated body; "
                             f"known: ['reference', {', '.join(map(repr, row_ids))}]")
        if sc.fidelity == "cw":
            if origin != "reference":
                raise ValueError("[plant].frame_origin must be 'reference' with the cw propagator")
            self._offset = 0
            self.propagator = make_propagator("cw", a_m=self.a_m, u0_rad=self.u0_rad, pos_m=pos0, vel_mps=vel0)
            self._origin_row = None
        elif sc.fidelity == "inertial":
            # the reference orbit: [orbit] (circular unless eccentricity > 0; u0 = argp + true anomaly)
            ecc, argp = float(getattr(o, "eccentricity", 0.0)), float(getattr(o, "argp_rad", 0.0))
            r_ref, v_ref = kepler_to_eci(self.a_m, ecc, o.inclination_rad, o.raan_rad, argp, self.u0_rad - argp)
            r_ref, v_ref = np.asarray(r_ref, float), np.asarray(v_ref, float)
            r, v = lvlh_to_eci(r_ref, v_ref, pos0, vel0)
            mass = [s.mass_kg for s in self.specs] + [b.mass_kg for b in self.prop_bodies]
            area = [s.area_m2 for s in self.specs] + [b.area_m2 for b in self.prop_bodies]
            cd = [s.drag_coefficient for s in self.specs] + [b.drag_coefficient for b in self.prop_bodies]
            self._offset = 1  # row 0: the reference orbit (drag-free point mass)
            r, v = np.vstack([r_ref, r]), np.vstack([v_ref, v])
            mass, area, cd = [1.0] + mass, [0.0] + area, [0.0] + cd
            self.propagator = make_propagator(
                "inertial", r_eci_m=r, v_eci_mps=v, mass_kg=np.asarray(mass), area_m2=np.asarray(area),
                cd=np.asarray(cd), j2=bool(sc.plant_options.get("j2", True)),
                drag=bool(sc.plant_options.get("atmospheric_drag", True)), thrust_frame="eci",
                max_step_s=float(sc.plant_options.get("max_integration_step_s", 10.0)))
            self._origin_row = 0 if origin == "reference" else 1 + row_ids.index(origin)
        else:
            raise ValueError(f"MissionWorld flies the cw and inertial propagators, not {sc.fidelity!r}")
        self._origin_thrust_eci: np.ndarray | None = None  # inertial: the origin row's last thrust + manoeuvre
        # [plant].command_frame: "lvlh" (default) commands in the scenario frame; "eci" (inertial only)
        # commands in ECI axes, applied unrotated (limits per axis act on ECI axes); the recorded
        # last_accel_mps2 is always rotated into the scenario frame (the origin's LVLH at the step's start)
        self.command_frame = str(sc.plant_options.get("command_frame", "lvlh"))
        if self.command_frame == "eci" and sc.fidelity != "inertial":
            raise ValueError("[plant].command_frame = 'eci' needs fidelity = 'inertial'")
        att = [i for i, s in enumerate(self.specs) if s.inertia_kgm2 is not None]
        self.att_index = np.asarray(att, dtype=int)
        self.attitude: AttitudePropagator | None = None
        if att:
            q0 = np.array([wxyz_to_xyzw(self.specs[i].attitude_q) for i in att])
            w0 = np.array([self.specs[i].angular_velocity_radps for i in att])
            inertia = np.array([np.diag(self.specs[i].inertia_kgm2) for i in att])
            tmax = np.array([self.specs[i].max_torque_nm or np.inf for i in att])
            self.attitude = AttitudePropagator(q0=q0, omega0_radps=w0, inertia_kgm2=inertia,
                                               max_torque_nm=tmax if np.all(np.isfinite(tmax)) else None)

    @staticmethod
    def _max_accel(s: Any, sc: PlantConfig) -> float:
        if s.max_accel_mps2 is not None:
            return float(s.max_accel_mps2)
        if s.max_force_n is not None:
            return float(s.max_force_n) / float(s.mass_kg)
        return float(sc.max_accel_mps2)

    # --- state ----------------------------------------------------------------------------------
    @property
    def u_rad(self) -> float:
        if self._u_at != self.steps_done:  # once a step (the osculating u of an inertial origin costs ~60 us)
            self._u, self._u_at = float(self.propagator.u_rad), self.steps_done
        return self._u

    def _rows_lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        if self._origin_row is None:
            return self.propagator.state()
        if self._rows_at != self.steps_done:  # once a step: the truth, the sensing and the body truths ask for them
            # the origin's thrust over the step that just ended turns its LVLH too (out of plane: about x)
            p, v = self.propagator.relative_lvlh(self._origin_row, self._origin_thrust_eci)  # type: ignore[attr-defined]
            self._rows, self._rows_at = (p[self._offset:], v[self._offset:]), self.steps_done
        return self._rows[0].copy(), self._rows[1].copy()

    def lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,3) spacecraft positions and velocities in the scenario frame."""
        p, v = self._rows_lvlh()
        n = len(self.ids)
        return (p, v) if len(p) == n else (p[:n], v[:n])

    def roe_m(self, lvlh: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """(N, 6) ROE in metres of the scenario-frame states (`lvlh`: this step's `lvlh()`, when the caller has it)."""
        pos, vel = self.lvlh() if lvlh is None else lvlh
        return roe_linear.lvlh_to_roe(pos, vel, self.u_rad, self.n_radps)

    def eci(self) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Inertial fidelity: (ids, ECI positions, ECI velocities) of every spacecraft, then every
        propagated body (the propagator's rows without the reference orbit)."""
        if self.fidelity != "inertial":
            raise ValueError("ECI states exist with fidelity = 'inertial' only")
        r, v = self.propagator.state()
        return self.ids + [b.id for b in self.prop_bodies], r[self._offset:], v[self._offset:]

    def attitude_wxyz(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(N,4) scalar-first attitude and (N,3) body rates of every spacecraft (NaN rows where not flown)."""
        if self.attitude is None:
            return None, None
        q, w = self.attitude.state()
        n = len(self.ids)
        qa, wa = np.full((n, 4), np.nan), np.full((n, 3), np.nan)
        qa[self.att_index], wa[self.att_index] = xyzw_to_wxyz(q), w
        return qa, wa

    def body_truth(self) -> list[BodyTruth]:
        """Every non-agent body now, in the scenario frame."""
        out = []
        p, v = self._rows_lvlh()
        n = len(self.ids)
        for k, b in enumerate(self.prop_bodies):
            out.append(BodyTruth(b, p[n + k], v[n + k], np.array([1.0, 0, 0, 0]), np.zeros(3)))
        key = (self.t_s, id(self.body_faults))
        if self._kinematic_at is None or self._kinematic_at[0] != key:
            self._kinematic_at = (key, [self._kinematic_truth(b) for b in self.kin_bodies])
        return out + self._kinematic_at[1]

    def _kinematic_truth(self, b: BodySpec) -> BodyTruth:
        """A kinematic body's pose at t_s (a function of time alone, so computed once per step for
        every caller: the truth, contacts and sensing kinds; its arrays are read-only)."""
        m = b.motion
        if b.id in self.body_faults:
            bt = BodyTruth(b, *kinematic_pose(m, self.body_faults[b.id], self.t_s))
        else:
            pos = np.asarray(m.position_m) + np.asarray(m.velocity_mps) * self.t_s
            axis = np.asarray(m.spin_axis)
            q_spin = quat_from_axis_angle(axis, m.spin_rate_radps * self.t_s)  # scalar-last
            q = xyzw_to_wxyz(quat_multiply(q_spin, wxyz_to_xyzw(m.attitude_q)))
            w_body = _rotate_to_body(q, axis * m.spin_rate_radps)
            bt = BodyTruth(b, pos, np.array(m.velocity_mps, float), q, w_body)
        for a in (bt.position_m, bt.velocity_mps, bt.attitude_q, bt.angular_velocity_radps):
            a.setflags(write=False)
        return bt

    # --- actuators and propagation ----------------------------------------------------------------
    def _plan_limits(self) -> None:
        """How `limit` limits (from limit_mode and max_accel_mps2): the spacecraft of each limit mode
        in one call (row by row the same arithmetic); when one mode covers them all, one call on the
        whole array without the gather and scatter, with one float for the limit when they share it."""
        self._limit_groups = [(limit_norm if mode == "norm" else limit_per_axis, rows, self.max_accel_mps2[rows])
                              for mode in sorted(set(self.limit_mode))
                              for rows in [np.array([i for i, m in enumerate(self.limit_mode) if m == mode])]]
        self._limit_all: tuple[Callable[..., np.ndarray], float | np.ndarray] | None = None
        if len(self._limit_groups) == 1:
            f, _rows, max_mps2 = self._limit_groups[0]
            self._limit_all = (f, float(max_mps2[0]) if (max_mps2 == max_mps2[0]).all() else max_mps2)

    def limit(self, accel_mps2: np.ndarray, all_alive: bool = False) -> np.ndarray:
        """The commands the actuators give: each limit mode's limit, zero for the dead (`all_alive`:
        the caller knows that nobody is)."""
        return self._limited(accel_mps2, all_alive)[0]

    def _limited(self, accel_mps2: np.ndarray, all_alive: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """`limit`'s commands and, when one norm limit covers every spacecraft, all alive and none
        over it, their norms (limits.limit_norm_rows), else None."""
        if self._limit_all is not None:
            f, max_all = self._limit_all
            if f is limit_norm and all_alive:
                return limit_norm_rows(np.asarray(accel_mps2, float), max_all)
            a = f(np.asarray(accel_mps2, float), max_all)  # (a new array)
        else:
            a = np.asarray(accel_mps2, float).copy()
            for f, rows, max_mps2 in self._limit_groups:
                a[rows] = f(a[rows], max_mps2)
        if not all_alive:
            a[~self.alive] = 0.0
        return a, None

    def step(self, accel_mps2: np.ndarray, dt_s: float, torque_nm: np.ndarray | None = None,
             all_alive: bool = False) -> None:
        """Advance by dt with commands (scenario frame; torque in each body frame) held over the step
        (`all_alive`: the caller knows that every spacecraft is alive)."""
        c0 = time.perf_counter()
        a, norm = self._limited(accel_mps2, all_alive)
        if self.actuation_faults is not None:
            a, norm = self.actuation_faults(a, self.steps_done), None
        self.last_accel_mps2 = a
        self.delta_v_mps += (row_norm(a) if norm is None else norm) * dt_s
        if self.prop_bodies or not a.flags.c_contiguous:
            acc = np.vstack([a] + [(manoeuvre_accel(b.motion.manoeuvres, self.t_s) + self._fault_accel(b.id))[None]
                                   for b in self.prop_bodies])
        else:
            acc = a  # (the spacecraft alone: np.vstack([a]) would be a copy of it)
        if self.fidelity == "inertial":
            r, v = self.propagator.state()
            o = self._origin_row
            acc_eci = lvlh_vector_to_eci(np.broadcast_to(r[o], acc.shape), np.broadcast_to(v[o], acc.shape), acc)
            if self.command_frame == "eci":
                n = len(self.ids)
                acc_eci[:n] = a                                   # ECI commands: applied as given
                self.last_accel_mps2 = a @ lvlh_basis(r[o], v[o]).T  # recorded in the scenario frame
            acc = np.vstack([np.zeros((1, 3)), acc_eci])
            self._origin_thrust_eci = acc[o].copy()
        self.propagator.step(acc, dt_s)
        if self.attitude is not None:
            tau = np.zeros((len(self.att_index), 3)) if torque_nm is None else np.asarray(torque_nm, float)[self.att_index]
            tau = np.where(self.alive[self.att_index, None], tau, 0.0)
            applied = self.attitude.step(tau, dt_s)
            self.last_torque_nm = np.zeros((len(self.ids), 3))
            self.last_torque_nm[self.att_index] = applied
        self.steps_done += 1
        self.t_s = self.steps_done * dt_s
        self.wall_s += time.perf_counter() - c0


    def _fault_accel(self, body_id: str) -> np.ndarray:
        """The body_manoeuvre accelerations of a propagated body at this step (scenario frame)."""
        a = np.zeros(3)
        for bf in self.body_faults.get(body_id, ()):
            if isinstance(bf.fault, BodyManoeuvre) and bf.window.active(self.steps_done):
                a = a + np.asarray(bf.fault.accel_mps2, float)
        return a


def kinematic_pose(m: Any, faults: list[BodyFault], t_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(position, velocity, attitude wxyz, body rates) of a kinematic body at t under body faults:
    its constant velocity plus each body_manoeuvre's closed-form displacement
    (plant/faults.py manoeuvre_displacement), and its spin segments composed in time order,
    q(t) = exp(a_k r_k T_k) ⊗ ... ⊗ exp(a_0 r_0 T_0) ⊗ q0 (spin_segments)."""
    pos = np.asarray(m.position_m, float) + np.asarray(m.velocity_mps, float) * t_s
    vel = np.asarray(m.velocity_mps, float).copy()
    for bf in faults:
        if isinstance(bf.fault, BodyManoeuvre):
            dp, dv = manoeuvre_displacement(np.asarray(bf.fault.accel_mps2, float), bf.t0_s, bf.t1_s, t_s)
            pos, vel = pos + dp, vel + dv
    q = wxyz_to_xyzw(m.attitude_q)
    axis, rate = np.asarray(m.spin_axis, float), float(m.spin_rate_radps)
    for axis, rate, dt in spin_segments(axis, rate, faults, t_s):
        q = quat_multiply(quat_from_axis_angle(axis, rate * dt), q)
    q_wxyz = xyzw_to_wxyz(q)
    return pos, vel, q_wxyz, _rotate_to_body(q_wxyz, axis * rate)


def _rotate_to_body(q_wxyz: np.ndarray, vec_frame: np.ndarray) -> np.ndarray:
    """R(q)^T v: a frame vector in body axes (q scalar-first, body -> frame)."""
    w, x, y, z = q_wxyz
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return r.T @ np.asarray(vec_frame, float)


register_world("cw", "inertial")(MissionWorld)  # the Cartesian scenarios with bodies and attitude (issue 11)
