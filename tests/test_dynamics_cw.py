"""Clohessy-Wiltshire propagator (plant/dynamics/cw.py) against independent references.

- the closed-form HCW solution written here in its other form (drift + oscillation constants,
  Vallado eq. 6-69 style), over a day at LEO and GEO, stepping at 1 s and 60 s: 1 mm;
- Phi and Gamma against the matrix exponential of A and of the augmented matrix [[A, B], [0, 0]];
- forced response against scipy solve_ivp (DOP853, rtol 1e-12) of the HCW ODE, constant and
  piecewise-constant accelerations;
- the linear ROE model (roe_linear.py, D'Amico's Gauss-variation input matrix, another derivation)
  with commands: same trajectory to 1e-6 m;
- sign: an along-track burn raises the orbit (x > 0) and drifts it backwards by -3 dv T per orbit;
  scaling: against nonlinear two-body motion the CW residual is quadratic in the separation
  (halving the formation quarters it), so a sign or factor error cannot hide in a tolerance.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from swarmhil.plant.dynamics import cw
from swarmhil.plant.dynamics.propagator import Propagator, make_propagator

MU = 3.986004418e14
A_LEO_M = 6878.0e3
A_GEO_M = 42164.0e3
DAY_S = 86400.0


def hcw_closed_form(x0: np.ndarray, n: float, t: float) -> np.ndarray:
    """HCW free motion, drift/oscillation form (rows of x0: x, y, z, vx, vy, vz)."""
    x, y, z, vx, vy, vz = x0.T
    c, s = np.cos(n * t), np.sin(n * t)
    k = 3.0 * x + 2.0 * vy / n  # amplitude of the in-plane oscillation's cosine part
    return np.stack(
        (
            4.0 * x + 2.0 * vy / n + vx / n * s - k * c,
            y - 2.0 * vx / n - 3.0 * (2.0 * n * x + vy) * t + 2.0 * k * s + 2.0 * vx / n * c,
            z * c + vz / n * s,
            vx * c + k * n * s,
            -3.0 * (2.0 * n * x + vy) + 2.0 * k * n * c - 2.0 * vx * s,
            -z * n * s + vz * c,
        ),
        axis=-1,
    )


def initial_states(a_m: float) -> np.ndarray:
    """Four craft: bounded, drifting, radial offset, cross-track, at ~1 km (LEO) / ~10 km (GEO) scale."""
    n = np.sqrt(MU / a_m**3)
    scale = 1.0e3 if a_m < 1e7 else 1.0e4
    x0 = np.array(
        [
            [0.3, -1.0, 0.2, 0.0, 0.0, 0.0],
            [0.2, 0.5, -0.4, 0.1, -0.6, 0.3],
            [1.0, 0.0, 0.0, 0.0, -2.0, 0.0],  # vy = -2 n x: bounded
            [-0.1, 0.2, 1.0, 0.05, 0.0, -0.7],
        ]
    )
    x0[:, :3] *= scale
    x0[:, 3:] *= scale * n
    x0[2, 4] = -2.0 * n * x0[2, 0]
    return x0


@pytest.mark.parametrize("a_m", [A_LEO_M, A_GEO_M], ids=["LEO", "GEO"])
@pytest.mark.parametrize("dt_s", [1.0, 60.0])
def test_free_motion_matches_closed_form_over_a_day(a_m: float, dt_s: float) -> None:
    x0 = initial_states(a_m)
    n = np.sqrt(MU / a_m**3)
    prop = make_propagator("cw", a_m=a_m, pos_m=x0[:, :3], vel_mps=x0[:, 3:], u0_rad=0.2)
    assert isinstance(prop, Propagator) and prop.frame == "lvlh"
    n_steps = int(DAY_S / dt_s)
    worst_m = worst_mps = 0.0
    for k in range(1, n_steps + 1):
        prop.step(None, dt_s)
        if k % int(3600.0 / dt_s) == 0:  # every hour
            pos, vel = prop.state()
            ref = hcw_closed_form(x0, n, k * dt_s)
            worst_m = max(worst_m, np.abs(pos - ref[:, :3]).max())
            worst_mps = max(worst_mps, np.abs(vel - ref[:, 3:]).max())
    assert prop.t_s == DAY_S
    assert prop.u_rad == 0.2 + n * DAY_S
    print(f"cw free a={a_m/1e3:.0f} km dt={dt_s:g} s: worst over a day {worst_m:.2e} m, {worst_mps:.2e} m/s")
    assert worst_m < 1e-3
    assert worst_mps < 1e-6


@pytest.mark.parametrize("a_m", [A_LEO_M, A_GEO_M], ids=["LEO", "GEO"])
@pytest.mark.parametrize("dt_s", [1.0, 60.0, 1000.0, 20000.0])
def test_phi_and_gamma_equal_matrix_exponentials(a_m: float, dt_s: float) -> None:
    """Phi = expm(A dt); [Phi Gamma; 0 I] = expm([[A, B], [0, 0]] dt) (Van Loan 1978)."""
    n = cw.mean_motion(a_m)
    a = cw.state_matrix(n)
    aug = np.zeros((9, 9))
    aug[:6, :6] = a
    aug[3:6, 6:9] = np.eye(3)
    e = expm(aug * dt_s)
    phi, gamma = cw.transition_matrix(n, dt_s), cw.zoh_input_matrix(n, dt_s)
    np.testing.assert_allclose(phi, e[:6, :6], rtol=1e-10, atol=1e-12 * np.abs(e[:6, :6]).max())
    np.testing.assert_allclose(gamma, e[:6, 6:], rtol=1e-10, atol=1e-12 * np.abs(e[:6, 6:]).max())
    # Gamma(dt) = int Phi B: its derivative in dt is Phi(dt) B (central difference, independent of expm)
    h = min(1e-3 * dt_s, 1.0)
    d_gamma = (cw.zoh_input_matrix(n, dt_s + h) - cw.zoh_input_matrix(n, dt_s - h)) / (2 * h)
    np.testing.assert_allclose(d_gamma, phi[:, 3:], rtol=1e-5, atol=1e-9 * np.abs(phi[:, 3:]).max())


def hcw_rhs(n: float, accel: np.ndarray):
    def f(_t: float, s: np.ndarray) -> np.ndarray:
        x, y, z, vx, vy, vz = s
        return np.array([vx, vy, vz, 3 * n * n * x + 2 * n * vy + accel[0], -2 * n * vx + accel[1], -n * n * z + accel[2]])

    return f


@pytest.mark.parametrize("a_m", [A_LEO_M, A_GEO_M], ids=["LEO", "GEO"])
def test_forced_response_against_solve_ivp(a_m: float) -> None:
    n = cw.mean_motion(a_m)
    period = 2 * np.pi / n
    x0 = initial_states(a_m)[1]
    rng = np.random.default_rng(7)
    # constant acceleration over one orbit, in one step and in 60 s steps
    accel = np.array([2e-5, -3e-5, 1e-5])
    ref = solve_ivp(hcw_rhs(n, accel), (0, period), x0, method="DOP853", rtol=1e-12, atol=1e-9).y[:, -1]
    one = make_propagator("cw", a_m=a_m, pos_m=x0[None, :3], vel_mps=x0[None, 3:])
    one.step(accel[None], period)
    many = make_propagator("cw", a_m=a_m, pos_m=x0[None, :3], vel_mps=x0[None, 3:])
    step_s = 60.0 if a_m < 1e7 else 600.0
    n_steps = int(round(period / step_s))
    for _ in range(n_steps):
        many.step(accel[None], period / n_steps)
    for prop in (one, many):
        pos, vel = prop.state()
        err_m = np.abs(pos[0] - ref[:3]).max()
        print(f"cw constant accel a={a_m/1e3:.0f} km: {err_m:.2e} m, {np.abs(vel[0] - ref[3:]).max():.2e} m/s")
        assert err_m < 1e-5 * max(1.0, np.abs(ref[:3]).max() / 1e4)
        assert np.abs(vel[0] - ref[3:]).max() < 1e-8
    # piecewise-constant: a new random command every step (several craft at once), one orbit
    x0s = initial_states(a_m)
    prop = make_propagator("cw", a_m=a_m, pos_m=x0s[:, :3], vel_mps=x0s[:, 3:])
    states = x0s.copy()
    for _ in range(n_steps):
        cmd = rng.normal(0.0, 3e-5, (4, 3))
        prop.step(cmd, step_s)
        states = np.array([
            solve_ivp(hcw_rhs(n, cmd[i]), (0, step_s), states[i], method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
            for i in range(4)
        ])
    pos, vel = prop.state()
    err_m, err_mps = np.abs(pos - states[:, :3]).max(), np.abs(vel - states[:, 3:]).max()
    print(f"cw piecewise-constant a={a_m/1e3:.0f} km, {n_steps} steps: {err_m:.2e} m, {err_mps:.2e} m/s")
    assert err_m < 1e-5 and err_mps < 1e-8


def test_same_trajectory_as_linear_roe_model_with_commands() -> None:
    """ROE (Gauss variations, exact ZOH) mapped to LVLH = HCW with the same commands (both exact)."""
    a_m = A_LEO_M
    rng = np.random.default_rng(3)
    roe = rng.normal(0.0, 500.0, (5, 6))
    lin = make_propagator("linear", a_m=a_m, inc_rad=1.7, raan_rad=0.3, u0_rad=0.4, roe_m=roe)
    hill = make_propagator("cw", a_m=a_m, u0_rad=0.4, roe_m=roe)
    worst = 0.0
    for _ in range(600):  # 10 h at 60 s
        cmd = rng.normal(0.0, 2e-5, (5, 3))
        lin.step(cmd, 60.0)
        hill.step(cmd, 60.0)
        (p1, v1), (p2, v2) = lin.state(), hill.state()
        worst = max(worst, np.abs(p1 - p2).max())
        assert np.abs(v1 - v2).max() < 1e-9
    assert lin.u_rad == hill.u_rad
    print(f"cw vs linear ROE, 10 h with commands: {worst:.2e} m")
    assert worst < 1e-6


def test_sign_along_track_burn_raises_orbit_and_drifts_back() -> None:
    """A short +y burn of dv: x > 0 after half an orbit (4 dv/n), y(T) = -3 dv T = -6 pi dv / n."""
    n = cw.mean_motion(A_LEO_M)
    period = 2 * np.pi / n
    dv = 0.01
    prop = cw.CwPropagator(A_LEO_M, np.zeros((1, 3)), np.zeros((1, 3)))
    prop.step(np.array([[0.0, dv / 1.0, 0.0]]), 1.0)  # 1 s burn
    prop.step(None, 0.5 * period - 1.0)
    pos, _ = prop.state()
    assert pos[0, 0] == pytest.approx(4.0 * dv / n, rel=1e-3)  # apogee of the raised orbit
    prop.step(None, 0.5 * period)
    pos, _ = prop.state()
    assert pos[0, 1] == pytest.approx(-6.0 * np.pi * dv / n, rel=1e-3)
    assert abs(pos[0, 0]) < 1e-3 * dv / n
    # radial +x burn: y = 2 dv/n (cos nt - 1), -4 dv/n after half an orbit, back to the origin after one
    prop = cw.CwPropagator(A_LEO_M, np.zeros((1, 3)), np.zeros((1, 3)))
    prop.step(np.array([[dv, 0.0, 0.0]]), 1.0)
    prop.step(None, 0.5 * period - 1.0)
    pos, _ = prop.state()
    assert pos[0, 1] == pytest.approx(-4.0 * dv / n, rel=1e-3)
    prop.step(None, 0.5 * period)
    assert np.abs(prop.state()[0]).max() < 2e-3 * dv / n


def _two_body_relative(a_m: float, rho0: np.ndarray, rho_dot0: np.ndarray, t_s: float) -> np.ndarray:
    """Nonlinear relative motion: chief and deputy integrated in ECI (point mass), deputy given in
    the chief's LVLH at t = 0 (frame built here with np.cross)."""
    n = np.sqrt(MU / a_m**3)
    r_c = np.array([a_m, 0.0, 0.0])
    v_c = np.array([0.0, n * a_m * np.cos(0.5), n * a_m * np.sin(0.5)])

    def lvlh(r, v):
        x = r / np.linalg.norm(r)
        z = np.cross(r, v)
        z /= np.linalg.norm(z)
        return np.stack((x, np.cross(z, x), z))

    rot = lvlh(r_c, v_c)
    omega = np.array([0.0, 0.0, n])
    r_d = r_c + rot.T @ rho0
    v_d = v_c + rot.T @ (rho_dot0 + np.cross(omega, rho0))

    def f(_t, y):
        out = np.empty(12)
        for k in (0, 6):
            r = y[k:k + 3]
            out[k:k + 3] = y[k + 3:k + 6]
            out[k + 3:k + 6] = -MU * r / np.linalg.norm(r) ** 3
        return out

    y = solve_ivp(f, (0, t_s), np.concatenate((r_c, v_c, r_d, v_d)), method="DOP853", rtol=1e-13, atol=1e-9).y[:, -1]
    return lvlh(y[:3], y[3:6]) @ (y[6:9] - y[:3])


def test_residual_against_nonlinear_two_body_is_quadratic_in_separation() -> None:
    a_m = A_LEO_M
    n = np.sqrt(MU / a_m**3)
    period = 2 * np.pi / n
    rho0 = np.array([400.0, -1500.0, 600.0])
    rho_dot0 = np.array([0.1, -2.0 * n * 400.0, -0.3])
    resid = []
    for scale in (1.0, 0.5):
        prop = make_propagator("cw", a_m=a_m, pos_m=scale * rho0[None], vel_mps=scale * rho_dot0[None])
        for _ in range(int(round(period / 60.0))):
            prop.step(None, period / round(period / 60.0))
        resid.append(np.linalg.norm(prop.state()[0][0] - _two_body_relative(a_m, scale * rho0, scale * rho_dot0, period)))
    ratio = resid[0] / resid[1]
    print(f"cw vs two-body after one orbit: {resid[0]:.3f} m at ~1.6 km, {resid[1]:.3f} m at half; ratio {ratio:.2f}")
    assert 1.0 < resid[0] < 100.0  # linearisation error, not an error of the model
    assert 3.6 < ratio < 4.4


def test_registry_errors() -> None:
    with pytest.raises(ValueError, match="unknown propagator 'hill'; known: cw, inertial, j2, linear"):
        make_propagator("hill", a_m=A_LEO_M)
    with pytest.raises(ValueError, match="takes no argument drag"):
        make_propagator("cw", a_m=A_LEO_M, roe_m=np.zeros((1, 6)), drag={"bc_m2pkg": 0.01})
    with pytest.raises(ValueError, match="needs a_m"):
        make_propagator("cw", roe_m=np.zeros((1, 6)))
    with pytest.raises(ValueError, match="either roe_m or pos_m"):
        make_propagator("cw", a_m=A_LEO_M)
    prop = make_propagator("cw", a_m=A_LEO_M, roe_m=np.zeros((2, 6)))
    with pytest.raises(ValueError, match=r"accel_mps2 must be \(2, 3\)"):
        prop.step(np.zeros((3, 3)), 1.0)
