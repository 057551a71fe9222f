"""Rigid-body attitude of N craft: quaternion kinematics and Euler's equations, RK4 sub-steps.

Conventions (the one place they are spelled for attitude):
- quaternion SCALAR-LAST, q = (x, y, z, w) = (sin(phi/2) e, cos(phi/2)), Hamilton product (as
  scipy.spatial.transform.Rotation.as_quat); q rotates BODY vectors into the inertial frame:
  v_I = q (x) v_B (x) q*, i.e. v_I = R(q) v_B (`quat_to_matrix`).
- body rate omega [rad/s] in body axes; torque [N m] in body axes; inertia [kg m^2] in body axes.

Equations (Schaub & Junkins, Analytical Mechanics of Space Systems, eq. 3.104 and 4.34;
Wertz, Spacecraft Attitude Determination and Control, eq. 16-2 and 17-1):
    q' = 1/2 q (x) (omega, 0)                     (kinematics)
    I omega' = tau - omega x (I omega)            (Euler's equations)
The torque command is held constant in body axes over the step and limited by norm
(`limits.limit_norm`, one budget per craft). Integration: classical RK4 (Hairer I, Table 1.2)
with sub-steps of at most `max_substep_s`, q renormalised after each sub-step.
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.plant.dynamics.frames import cross
from swarmhil.plant.dynamics.limits import limit_norm
from swarmhil.plant.dynamics.step_clock import StepClock


def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p (x) q, scalar-last, (..., 4): (p_w q_v + q_w p_v + p_v x q_v, p_w q_w - p_v . q_v)."""
    pv, pw = p[..., :3], p[..., 3:4]
    qv, qw = q[..., :3], q[..., 3:4]
    vec = pw * qv + qw * pv + cross(pv, qv)
    sca = pw * qw - np.sum(pv * qv, axis=-1, keepdims=True)
    return np.concatenate((vec, sca), axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """q* = (-x, -y, -z, w)."""
    return np.concatenate((-q[..., :3], q[..., 3:4]), axis=-1)


def quat_from_axis_angle(axis: np.ndarray, angle_rad: np.ndarray | float) -> np.ndarray:
    """Unit quaternion of a rotation by angle about axis (..., 3) (normalised here): (sin(a/2) e, cos(a/2))."""
    axis = np.asarray(axis, dtype=float)
    e = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle_rad, dtype=float)[..., None]
    return np.concatenate((np.sin(half) * e, np.cos(half)), axis=-1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """R(q), (..., 3, 3), body -> inertial (Schaub & Junkins eq. 3.98, scalar-last)."""
    x, y, z, w = (q[..., k] for k in range(4))
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)), axis=-1),
            np.stack((2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)), axis=-1),
            np.stack((2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)), axis=-1),
        ),
        axis=-2,
    )


def attitude_rates(
    q: np.ndarray, omega: np.ndarray, inertia: np.ndarray, inertia_inv: np.ndarray, torque: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(q', omega') = (1/2 q (x) (omega, 0), I^-1 (tau - omega x I omega)); shapes (N,4), (N,3), (N,3,3).

    q (x) (omega, 0) = (q_w omega + q_v x omega, -q_v . omega) (the Hamilton product, written out).
    """
    qv, qw = q[:, :3], q[:, 3:4]
    q_dot = np.empty_like(q)
    q_dot[:, :3] = 0.5 * (qw * omega + cross(qv, omega))
    q_dot[:, 3] = -0.5 * np.sum(qv * omega, axis=1)
    h_body = np.matmul(inertia, omega[:, :, None])[:, :, 0]
    omega_dot = np.matmul(inertia_inv, (torque - cross(omega, h_body))[:, :, None])[:, :, 0]
    return q_dot, omega_dot


def rk4_attitude_step(
    q: np.ndarray, omega: np.ndarray, inertia: np.ndarray, inertia_inv: np.ndarray, torque: np.ndarray, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """One classical RK4 step of `attitude_rates` (torque constant), then q <- q / |q|."""
    k1q, k1w = attitude_rates(q, omega, inertia, inertia_inv, torque)
    k2q, k2w = attitude_rates(q + 0.5 * h * k1q, omega + 0.5 * h * k1w, inertia, inertia_inv, torque)
    k3q, k3w = attitude_rates(q + 0.5 * h * k2q, omega + 0.5 * h * k2w, inertia, inertia_inv, torque)
    k4q, k4w = attitude_rates(q + h * k3q, omega + h * k3w, inertia, inertia_inv, torque)
    q1 = q + (h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
    w1 = omega + (h / 6.0) * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
    return q1 / np.linalg.norm(q1, axis=-1, keepdims=True), w1


def _inertia_tensors(inertia_kgm2: np.ndarray, n: int) -> np.ndarray:
    """Accept (3,) principal moments, (3, 3) shared, (N, 3) principal per craft or (N, 3, 3); return (N, 3, 3)."""
    j = np.asarray(inertia_kgm2, dtype=float)
    if j.shape == (3,) or j.shape == (n, 3):
        j = np.broadcast_to(j, (n, 3))[:, :, None] * np.eye(3)
    elif j.shape == (3, 3):
        j = np.broadcast_to(j, (n, 3, 3)).copy()
    if j.shape != (n, 3, 3):
        raise ValueError(f"inertia_kgm2 must be (3,), (3, 3), ({n}, 3) or ({n}, 3, 3), got {j.shape}")
    if not np.allclose(j, np.swapaxes(j, -1, -2)) or np.any(np.linalg.eigvalsh(j) <= 0.0):
        raise ValueError("inertia_kgm2 must be symmetric positive definite for every craft")
    return j


class AttitudePropagator:
    """Attitude (q scalar-last, body -> inertial) and body rate of N rigid craft (module docstring).

    `step(torque_nm (N, 3) body, dt_s)` holds the torque (after the norm limit `max_torque_nm`, scalar
    or (N,), None = unlimited) over the step and returns the torque applied.
    """

    def __init__(
        self, *, q0: np.ndarray, omega0_radps: np.ndarray, inertia_kgm2: np.ndarray,
        max_torque_nm: float | np.ndarray | None = None, max_substep_s: float = 0.05,
    ) -> None:
        q = np.array(q0, dtype=float, ndmin=2)
        w = np.array(omega0_radps, dtype=float, ndmin=2)
        if q.ndim != 2 or q.shape[1] != 4 or w.shape != (q.shape[0], 3):
            raise ValueError(f"q0 must be (N, 4) and omega0_radps (N, 3), got {q.shape} and {w.shape}")
        norm = np.linalg.norm(q, axis=1)
        if np.any(np.abs(norm - 1.0) > 1e-6):
            raise ValueError(f"q0 must be unit quaternions, norms {norm}")
        if not max_substep_s > 0.0:
            raise ValueError(f"max_substep_s must be > 0, got {max_substep_s!r}")
        self._q = q / norm[:, None]
        self._omega = w
        self.inertia_kgm2 = _inertia_tensors(inertia_kgm2, q.shape[0])
        self._inertia_inv = np.linalg.inv(self.inertia_kgm2)
        self.max_torque_nm = max_torque_nm
        self.max_substep_s = float(max_substep_s)
        self._clock = StepClock()

    @property
    def n_craft(self) -> int:
        return self._q.shape[0]

    @property
    def t_s(self) -> float:
        return self._clock.t_s

    def step(self, torque_nm: np.ndarray | None, dt_s: float) -> np.ndarray:
        """Advance by dt_s with the body torque (N, 3) [N m] held; returns the (limited) torque applied."""
        n = self.n_craft
        tau = np.zeros((n, 3)) if torque_nm is None else np.asarray(torque_nm, dtype=float)
        if tau.shape != (n, 3):
            raise ValueError(f"torque_nm must be ({n}, 3), got {tau.shape}")
        if self.max_torque_nm is not None:
            tau = limit_norm(tau, self.max_torque_nm)
        n_sub = max(1, math.ceil(dt_s / self.max_substep_s - 1e-12))
        h = dt_s / n_sub
        q, w = self._q, self._omega
        for _ in range(n_sub):
            q, w = rk4_attitude_step(q, w, self.inertia_kgm2, self._inertia_inv, tau, h)
        self._q, self._omega = q, w
        self._clock.advance(dt_s)
        return tau

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Quaternions (N, 4) scalar-last body -> inertial, body rates (N, 3) [rad/s] (copies)."""
        return self._q.copy(), self._omega.copy()

    def angular_momentum_inertial(self) -> np.ndarray:
        """H = R(q) I omega [N m s], (N, 3), in the inertial frame (constant without torque)."""
        h_body = np.einsum("nij,nj->ni", self.inertia_kgm2, self._omega)
        return np.einsum("nij,nj->ni", quat_to_matrix(self._q), h_body)

    def kinetic_energy(self) -> np.ndarray:
        """T = 1/2 omega . I omega [J], (N,)."""
        return 0.5 * np.einsum("ni,nij,nj->n", self._omega, self.inertia_kgm2, self._omega)
