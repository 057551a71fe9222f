"""Inertial two-body + J2 + drag propagator (plant/dynamics/inertial.py) against independent physics.

The reference is written again here (J2 as 3/2 J2 mu R^2/r^5 ((5 z^2/r^2 - 1) r - 2 z k), drag with
np.cross) and integrated with scipy solve_ivp DOP853 (rtol 1e-13, atol 1e-9), restarted at every
command change. Tolerances in metres and m/s.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from swarmhil.plant.dynamics.absolute_j2 import kepler_to_eci, qns_to_eci, roe_to_absolute_elements
from swarmhil.plant.dynamics.inertial import InertialPropagator
from swarmhil.plant.dynamics.propagator import Propagator, make_propagator

MU = 3.986004418e14
RE = 6378137.0
J2_EGM = 1.08262668e-3
OMEGA_E = 7.292115e-5
A_LEO_M = 6878.0e3


def accel_ref(r: np.ndarray, v: np.ndarray, bc: np.ndarray | None, j2: bool = True) -> np.ndarray:
    rn = np.linalg.norm(r, axis=1, keepdims=True)
    acc = -MU * r / rn**3
    if j2:
        z = r[:, 2:3]
        acc = acc + 1.5 * J2_EGM * MU * RE**2 / rn**5 * ((5 * z**2 / rn**2 - 1) * r - 2 * z * np.array([0.0, 0.0, 1.0]))
    if bc is not None:
        v_rel = v - np.cross(np.array([0.0, 0.0, OMEGA_E]), r)
        rho = 6.967e-13 * np.exp(-(rn[:, 0] - RE - 500e3) / 63822.0)
        acc = acc - (0.5 * rho * bc * np.linalg.norm(v_rel, axis=1))[:, None] * v_rel
    return acc


def reference(y0: np.ndarray, t_s: float, bc: np.ndarray | None, cmd_eci: np.ndarray, j2: bool = True) -> np.ndarray:
    def f(_t, y):
        s = y.reshape(-1, 6)
        return np.hstack((s[:, 3:], accel_ref(s[:, :3], s[:, 3:], bc, j2) + cmd_eci)).ravel()

    sol = solve_ivp(f, (0.0, t_s), y0.ravel(), method="DOP853", rtol=1e-13, atol=1e-9)
    return sol.y[:, -1].reshape(-1, 6)


def swarm(a_m: float = A_LEO_M, e: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    r, v = kepler_to_eci(a_m + np.array([0.0, 200.0, -500.0]), e + np.array([0.0, 1e-5, 2e-5]),
                         np.radians(97.4) + np.array([0.0, 1e-4, 0.0]), 0.3, 0.2, 0.5 + np.array([0.0, -1e-4, 2e-4]))
    return r, v


CRAFT = {"mass_kg": np.array([100.0, 12.0, 500.0]), "area_m2": np.array([1.0, 0.1, 8.0]), "cd": np.array([2.2, 2.0, 2.4])}


@pytest.mark.parametrize("e", [0.0, 0.1], ids=["circular", "e=0.1"])
def test_j2_drag_thrust_against_solve_ivp_one_orbit(e: float) -> None:
    a_m = A_LEO_M if e == 0.0 else 7500.0e3  # e = 0.1: perigee at 372 km
    r, v = swarm(a_m, e)
    prop = make_propagator("inertial", r_eci_m=r, v_eci_mps=v, **CRAFT)
    assert isinstance(prop, Propagator) and prop.frame == "eci"
    bc = CRAFT["cd"] * CRAFT["area_m2"] / CRAFT["mass_kg"]
    np.testing.assert_allclose(prop.ballistic_coefficient_m2pkg, bc, rtol=1e-15)
    period = 2 * np.pi * np.sqrt(a_m**3 / MU)
    step_s, n_steps = 60.0, int(period // 60.0) + 1
    rng = np.random.default_rng(5)
    y = np.hstack((r, v))
    for k in range(n_steps):
        cmd = rng.normal(0.0, 1e-4, (3, 3)) if k % 10 < 3 else np.zeros((3, 3))  # burns and coasts
        prop.step(cmd, step_s)
        y = reference(y, step_s, bc, cmd)
    pos, vel = prop.state()
    err_m, err_mps = np.abs(pos - y[:, :3]).max(), np.abs(vel - y[:, 3:]).max()
    print(f"inertial J2+drag+thrust e={e}: one orbit ({n_steps} x 60 s, max_step 30 s): {err_m:.2e} m, {err_mps:.2e} m/s")
    assert err_m < 1e-3 and err_mps < 1e-6
    # drag was on and mattered: without it the orbit differs by far more than the tolerance
    y_nodrag = np.hstack((r, v))
    y_nodrag = reference(y_nodrag, n_steps * step_s, None, np.zeros((3, 3)))
    y_coast = reference(np.hstack((r, v)), n_steps * step_s, bc, np.zeros((3, 3)))
    assert np.abs(y_nodrag[:, :3] - y_coast[:, :3]).max() > 0.1


def test_two_body_eccentric_against_kepler() -> None:
    """J2 and drag off, e = 0.1: Kepler's equation gives the state at any time (Vallado alg. 10)."""
    a_m, e = 7500.0e3, 0.1
    n = np.sqrt(MU / a_m**3)
    prop = InertialPropagator(r_eci_m=kepler_to_eci(a_m, e, 0.9, 0.3, 0.2, 0.0)[0][None],
                              v_eci_mps=kepler_to_eci(a_m, e, 0.9, 0.3, 0.2, 0.0)[1][None],
                              mass_kg=10.0, j2=False, drag=False, max_step_s=10.0)
    worst = 0.0
    for k in range(1, 7):
        prop.step(None, 2 * np.pi / n / 6)
        m = n * prop.t_s
        ecc = m
        for _ in range(30):
            ecc = ecc - (ecc - e * np.sin(ecc) - m) / (1 - e * np.cos(ecc))
        nu = 2 * np.arctan2(np.sqrt(1 + e) * np.sin(ecc / 2), np.sqrt(1 - e) * np.cos(ecc / 2))
        r_ref, _ = kepler_to_eci(a_m, e, 0.9, 0.3, 0.2, nu)
        worst = max(worst, np.linalg.norm(prop.state()[0][0] - r_ref))
    print(f"inertial two-body e=0.1 vs Kepler, one orbit, 10 s steps: {worst:.2e} m")
    assert worst < 1e-3


def energy_j2(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v^2/2 + V, V = -mu/r [1 - J2 (R/r)^2 P2(z/r)], the J2 field's energy (static in ECI)."""
    rn = np.linalg.norm(r, axis=-1)
    p2 = 0.5 * (3 * (r[..., 2] / rn) ** 2 - 1)
    return 0.5 * np.sum(v * v, axis=-1) - MU / rn * (1 - J2_EGM * (RE / rn) ** 2 * p2)


def test_drag_off_energy_and_polar_angular_momentum_conserved() -> None:
    """Without drag and thrust, the J2 field is axisymmetric and static: E and h_z are constant."""
    for a_m, e in ((A_LEO_M, 0.0), (7500.0e3, 0.1)):
        r, v = swarm(a_m, e)
        prop = InertialPropagator(r_eci_m=r, v_eci_mps=v, drag=False, **CRAFT)
        e0, hz0 = energy_j2(r, v), np.cross(r, v)[:, 2]
        for _ in range(24):
            prop.step(None, 3600.0)  # one day
        r1, v1 = prop.state()
        de = np.abs(energy_j2(r1, v1) / e0 - 1).max()
        dh = np.abs(np.cross(r1, v1)[:, 2] / hz0 - 1).max()
        print(f"inertial J2 no drag, a={a_m/1e3:.0f} km e={e}, one day: |dE/E| {de:.1e}, |dh_z/h_z| {dh:.1e}")
        assert de < 1e-12 and dh < 1e-12
        # the energy is the J2 one: the Keplerian energy alone is not conserved to this level
        kep = 0.5 * np.sum(v1 * v1, axis=1) - MU / np.linalg.norm(r1, axis=1)
        assert np.abs(kep / (0.5 * np.sum(v * v, axis=1) - MU / np.linalg.norm(r, axis=1)) - 1).max() > 1e-6
    # drag on: energy decreases, in proportion to each craft's ballistic coefficient
    r, v = swarm()
    prop = InertialPropagator(r_eci_m=r, v_eci_mps=v, **CRAFT)
    for _ in range(6):
        prop.step(None, 1000.0)
    de = energy_j2(*prop.state()) - energy_j2(r, v)
    assert np.all(de < 0)
    bc = CRAFT["cd"] * CRAFT["area_m2"] / CRAFT["mass_kg"]
    np.testing.assert_allclose(de / de[0], bc / bc[0], rtol=2e-2)  # loss proportional to B


def test_relative_lvlh_and_lvlh_thrust_match_absolute_j2_plant() -> None:
    """Chief + deputies from ROE: same orbits and relative states as the j2 propagator (same RHS)."""
    ref_el = np.array([A_LEO_M, 0.5, 0.0, 0.0, np.radians(97.4), 0.3])
    roe = np.random.default_rng(2).normal(0.0, 400.0, (4, 6))
    r, v = qns_to_eci(np.vstack((ref_el, roe_to_absolute_elements(ref_el, roe))))
    drag = {"bc_m2pkg": 0.01, "bc_ref_m2pkg": 0.01}
    j2p = make_propagator("j2", a_m=A_LEO_M, inc_rad=ref_el[4], raan_rad=0.3, u0_rad=0.5, roe_m=roe, drag=drag)
    ine = make_propagator("inertial", r_eci_m=r, v_eci_mps=v, mass_kg=100.0, area_m2=1.0 / 2.2, cd=2.2,
                          thrust_frame="lvlh")
    rng = np.random.default_rng(4)
    for _ in range(60):
        cmd = rng.normal(0.0, 1e-4, (4, 3))
        j2p.step(cmd, 30.0)
        ine.step(np.vstack((np.zeros(3), cmd)), 30.0)
    rho, rho_dot = ine.relative_lvlh(0)
    p_j2, v_j2 = j2p.state()
    assert np.abs(rho[0]).max() == 0.0
    err = np.abs(rho[1:] - p_j2).max()
    print(f"inertial relative_lvlh vs j2 propagator, 30 min with LVLH thrust: {err:.2e} m")
    assert err < 1e-6 and np.abs(rho_dot[1:] - v_j2).max() < 1e-9
    assert ine.u_rad == pytest.approx(j2p.u_rad, abs=1e-12)
    # another chief: craft 0 seen from craft 2 is minus craft 2 seen from craft 0, to first order
    rho2, _ = ine.relative_lvlh(2)
    np.testing.assert_allclose(rho2[2], 0.0, atol=0.0)
    np.testing.assert_allclose(rho2[0], -rho[2], atol=1e-3 * np.linalg.norm(rho[2]))


def test_force_command_is_accel_times_mass() -> None:
    r, v = swarm()
    a = InertialPropagator(r_eci_m=r, v_eci_mps=v, **CRAFT)
    f = InertialPropagator(r_eci_m=r, v_eci_mps=v, **CRAFT)
    accel = np.array([[1e-3, 0.0, 0.0], [0.0, -2e-3, 0.0], [0.0, 0.0, 5e-4]])
    a.step(accel, 60.0)
    f.step_force(accel * CRAFT["mass_kg"][:, None], 60.0)
    np.testing.assert_allclose(f.state()[0], a.state()[0], rtol=0, atol=1e-9)


def test_bad_arguments() -> None:
    r, v = swarm()
    with pytest.raises(ValueError, match="mass_kg must be a scalar or one value per craft"):
        InertialPropagator(r_eci_m=r, v_eci_mps=v, mass_kg=np.ones(2))
    with pytest.raises(ValueError, match="mass_kg must be > 0"):
        InertialPropagator(r_eci_m=r, v_eci_mps=v, mass_kg=0.0)
    with pytest.raises(ValueError, match="thrust_frame"):
        InertialPropagator(r_eci_m=r, v_eci_mps=v, mass_kg=1.0, thrust_frame="body")
    with pytest.raises(ValueError, match="takes no argument bc_m2pkg"):
        make_propagator("inertial", r_eci_m=r, v_eci_mps=v, mass_kg=1.0, bc_m2pkg=0.01)
