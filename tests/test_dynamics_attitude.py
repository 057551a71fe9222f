"""Rigid-body attitude (plant/dynamics/attitude.py) against closed forms and invariants.

- quaternion convention against scipy.spatial.transform.Rotation (scalar-last, active);
- torque-free axisymmetric body against the analytic precession (Schaub & Junkins sec. 4.5):
  R(t) = Rot(H_hat, |H|/I_t t) R(0) Rot(z, (I_t - I_a) w_z / I_t t), w(t) = Rot(z, -psi_dot t) w(0);
- torque-free asymmetric body: kinetic energy and inertial angular momentum constant to 1e-9 relative
  over 1000 s;
- constant torque about a principal axis: w = w0 + tau/I t, rotation angle w0 t + tau/(2 I) t^2;
- torque limit by norm.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarmhil.plant.dynamics.attitude import (
    AttitudePropagator,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_to_matrix,
)


def rot_angle(r_a: np.ndarray, r_b: np.ndarray) -> np.ndarray:
    """Angle [rad] of the rotation r_a^T r_b, (N,)."""
    return Rotation.from_matrix(np.swapaxes(r_a, -1, -2) @ r_b).magnitude()


def test_quaternion_convention_matches_scipy() -> None:
    rng = np.random.default_rng(0)
    q = Rotation.random(5, random_state=1).as_quat()  # scalar-last
    np.testing.assert_allclose(quat_to_matrix(q), Rotation.from_quat(q).as_matrix(), atol=1e-15)
    p = Rotation.random(5, random_state=2).as_quat()
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(p, q)), (Rotation.from_quat(p) * Rotation.from_quat(q)).as_matrix(), atol=1e-15)
    axis, angle = rng.normal(size=(5, 3)), rng.uniform(-3, 3, 5)
    np.testing.assert_allclose(quat_to_matrix(quat_from_axis_angle(axis, angle)),
                               Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=1)[:, None] * angle[:, None]).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(quat_multiply(q, quat_conjugate(q)), np.tile([0, 0, 0, 1.0], (5, 1)), atol=1e-15)


def test_torque_free_axisymmetric_precession() -> None:
    it = np.array([10.0, 10.0, 4.0])   # transverse moments
    ia = np.array([20.0, 4.0, 10.0])   # axial: oblate, prolate, sphere
    inertia = np.stack([np.diag([a, a, b]) for a, b in zip(it, ia)])
    w0 = np.array([[0.02, -0.01, 0.1], [0.03, 0.02, -0.15], [0.05, 0.0, 0.05]])
    q0 = Rotation.random(3, random_state=3).as_quat()
    prop = AttitudePropagator(q0=q0, omega0_radps=w0, inertia_kgm2=inertia, max_substep_s=0.05)
    r0 = quat_to_matrix(q0)
    h_i = np.einsum("nij,nj->ni", r0, np.einsum("nij,nj->ni", inertia, w0))
    omega_p = np.linalg.norm(h_i, axis=1) / it
    psi_dot = (it - ia) * w0[:, 2] / it
    worst_rad = worst_w = 0.0
    for _ in range(10):
        prop.step(None, 100.0)
        t = prop.t_s
        r_prec = Rotation.from_rotvec(h_i / np.linalg.norm(h_i, axis=1)[:, None] * (omega_p * t)[:, None]).as_matrix()
        r_spin = Rotation.from_rotvec(np.array([0, 0, 1.0]) * (psi_dot * t)[:, None]).as_matrix()
        q, w = prop.state()
        worst_rad = max(worst_rad, rot_angle(quat_to_matrix(q), r_prec @ r0 @ r_spin).max())
        w_ref = np.einsum("nji,nj->ni", r_spin, w0)  # Rot(z, -psi_dot t) w0
        worst_w = max(worst_w, np.abs(w - w_ref).max())
    print(f"attitude axisymmetric precession, 1000 s, 0.05 s RK4: {worst_rad:.1e} rad, {worst_w:.1e} rad/s")
    assert worst_rad < 1e-8 and worst_w < 1e-10


def test_torque_free_invariants_asymmetric() -> None:
    inertia = np.array([[[12.0, 0.5, -0.3], [0.5, 8.0, 0.2], [-0.3, 0.2, 5.0]], np.diag([3.0, 2.0, 1.0])])
    w0 = np.array([[0.1, -0.2, 0.3], [0.01, 0.3, 0.02]])  # second: near the unstable intermediate axis
    prop = AttitudePropagator(q0=Rotation.random(2, random_state=4).as_quat(), omega0_radps=w0,
                              inertia_kgm2=inertia, max_substep_s=0.05)
    t0, h0 = prop.kinetic_energy(), prop.angular_momentum_inertial()
    swing = 0.0
    for _ in range(100):
        prop.step(None, 10.0)
        swing = max(swing, abs(prop.state()[1][1, 1] - w0[1, 1]))
    de = np.abs(prop.kinetic_energy() / t0 - 1).max()
    dh = (np.linalg.norm(prop.angular_momentum_inertial() - h0, axis=1) / np.linalg.norm(h0, axis=1)).max()
    q, w = prop.state()
    print(f"attitude torque-free asymmetric, 1000 s: |dT/T| {de:.1e}, |dH|/|H| {dh:.1e}")
    assert de < 1e-9 and dh < 1e-9
    assert np.abs(np.linalg.norm(q, axis=1) - 1).max() < 1e-15
    assert swing > 0.3  # the intermediate-axis body did tumble (w_y changed sign): the test is not trivial


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_constant_torque_about_principal_axis(axis: int) -> None:
    moments = np.array([4.0, 6.0, 9.0])
    tau, w0, t_end = 0.002, 0.01, 300.0  # up to 0.16 rad/s
    e = np.eye(3)[axis]
    q0 = Rotation.random(random_state=5).as_quat()[None]
    prop = AttitudePropagator(q0=q0, omega0_radps=(w0 * e)[None], inertia_kgm2=moments, max_substep_s=0.05)
    for _ in range(30):
        prop.step((tau * e)[None], t_end / 30)
    q, w = prop.state()
    angle = w0 * t_end + 0.5 * tau / moments[axis] * t_end**2
    q_ref = quat_multiply(q0, quat_from_axis_angle(e, angle))  # body-axis rotation composes on the right
    err = rot_angle(quat_to_matrix(q), quat_to_matrix(q_ref))[0]
    print(f"attitude constant torque axis {axis}: {angle:.1f} rad turned, error {err:.1e} rad")
    np.testing.assert_allclose(w[0], (w0 + tau / moments[axis] * t_end) * e, atol=1e-12)
    assert err < 1e-9


def test_torque_limited_by_norm() -> None:
    prop = AttitudePropagator(q0=np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0]]), omega0_radps=np.zeros((2, 3)),
                              inertia_kgm2=np.array([2.0, 2.0, 2.0]), max_torque_nm=np.array([0.1, 1.0]))
    applied = prop.step(np.array([[0.3, 0.4, 0.0], [0.3, 0.4, 0.0]]), 1.0)
    np.testing.assert_allclose(applied, [[0.06, 0.08, 0.0], [0.3, 0.4, 0.0]], atol=1e-15)
    np.testing.assert_allclose(prop.state()[1], applied / 2.0, atol=1e-15)  # w = tau t / I, t = 1 s
    with pytest.raises(ValueError, match="symmetric positive definite"):
        AttitudePropagator(q0=[0, 0, 0, 1.0], omega0_radps=[0, 0, 0.0], inertia_kgm2=np.array([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="unit quaternions"):
        AttitudePropagator(q0=[0, 0, 1.0, 1.0], omega0_radps=[0, 0, 0.0], inertia_kgm2=np.ones(3))
