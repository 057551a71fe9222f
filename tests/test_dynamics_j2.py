"""Nonlinear ECI plant (plant/dynamics/absolute_j2.py) against independent physics.

The references are written here again, in a different form from the module: the J2 acceleration
as 3/2 J2 mu R^2/r^5 ((5 z^2/r^2 - 1) r - 2 z k), the LVLH frame by np.cross, the drag density,
and a tight adaptive integration (scipy DOP853, rtol 1e-13) of the full ECI state, step by step
with each spacecraft's LVLH command rotated by its own LVLH frame. Tolerances in metres and m/s.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from swarmhil.plant.dynamics.absolute_j2 import (
    AbsoluteJ2Plant,
    eci_to_lvlh,
    kepler_to_eci,
    qns_to_eci,
    roe_to_absolute_elements,
)
from swarmhil.plant.dynamics.roe_linear import LinearRoePlant, roe_to_lvlh

MU = 3.986004418e14
RE = 6378137.0
J2_EGM = 1.08262668e-3
OMEGA_E = 7.292115e-5
A_M = 6878137.0
INC_RAD = np.radians(97.4)
RAAN_RAD = 0.3
U0_RAD = 0.5
N_RADPS = np.sqrt(MU / A_M**3)
PERIOD_S = 2 * np.pi / N_RADPS
DT_S = 10.0


# ------------------------------------------------------------------ independent reference model


def accel_ref(r: np.ndarray, v: np.ndarray, j2: bool, bc: np.ndarray | None) -> np.ndarray:
    rn = np.linalg.norm(r, axis=1, keepdims=True)
    acc = -MU * r / rn**3
    if j2:
        z = r[:, 2:3]
        k_hat = np.array([0.0, 0.0, 1.0])
        acc = acc + 1.5 * J2_EGM * MU * RE**2 / rn**5 * ((5 * z**2 / rn**2 - 1) * r - 2 * z * k_hat)
    if bc is not None:
        v_rel = v - np.cross(np.array([0.0, 0.0, OMEGA_E]), r)
        rho = 6.967e-13 * np.exp(-(rn[:, 0] - RE - 500e3) / 63822.0)
        acc = acc - (0.5 * rho * bc * np.linalg.norm(v_rel, axis=1))[:, None] * v_rel
    return acc


def lvlh_rows(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotation ECI -> LVLH, rows x_hat (radial), y_hat, z_hat (orbit normal)."""
    x_hat = r / np.linalg.norm(r, axis=-1, keepdims=True)
    h = np.cross(r, v)
    z_hat = h / np.linalg.norm(h, axis=-1, keepdims=True)
    return np.stack((x_hat, np.cross(z_hat, x_hat), z_hat), axis=-2)


def reference_step(y: np.ndarray, accel_lvlh: np.ndarray, dt: float, j2: bool, bc) -> np.ndarray:
    """Integrate state rows (ref, sc...) of (r, v) over dt with rtol 1e-13; sc thrust in own LVLH."""

    def f(_t, yf):
        s = yf.reshape(-1, 6)
        r, v = s[:, :3], s[:, 3:]
        acc = accel_ref(r, v, j2, bc)
        acc[1:] += np.einsum("nij,ni->nj", lvlh_rows(r[1:], v[1:]), accel_lvlh)
        return np.hstack((v, acc)).ravel()

    sol = solve_ivp(f, (0.0, dt), y.ravel(), method="DOP853", rtol=1e-13, atol=1e-9)
    assert sol.success
    return sol.y[:, -1].reshape(-1, 6)


def relative_position(y: np.ndarray) -> np.ndarray:
    rot = lvlh_rows(y[0, :3], y[0, 3:])
    return (y[1:, :3] - y[0, :3]) @ rot.T


def initial_roe(seed: int, n_sc: int, scale_m: float) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n_sc, 6)) * scale_m


# --------------------------------------------------------------------------- element mappings


def test_kepler_to_eci_circular_and_eccentric() -> None:
    a, inc, raan, u = 7.0e6, 1.2, 0.4, 2.1
    r, v = kepler_to_eci(a, 0.0, inc, raan, 0.0, u)
    expected = a * np.array([
        np.cos(raan) * np.cos(u) - np.sin(raan) * np.sin(u) * np.cos(inc),
        np.sin(raan) * np.cos(u) + np.cos(raan) * np.sin(u) * np.cos(inc),
        np.sin(u) * np.sin(inc),
    ])
    np.testing.assert_allclose(r, expected, rtol=0, atol=1e-6)
    assert np.linalg.norm(v) == pytest.approx(np.sqrt(MU / a), rel=1e-14)
    h_hat = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
    h_expected = [np.sin(raan) * np.sin(inc), -np.cos(raan) * np.sin(inc), np.cos(inc)]
    np.testing.assert_allclose(h_hat, h_expected, atol=1e-14)
    # Eccentric: vis-viva, the eccentricity vector and r = p / (1 + e cos nu).
    e, argp, nu = 0.1, 0.7, 1.3
    r, v = kepler_to_eci(a, e, inc, raan, argp, nu)
    rn = np.linalg.norm(r)
    assert np.dot(v, v) == pytest.approx(MU * (2 / rn - 1 / a), rel=1e-13)
    e_vec = ((np.dot(v, v) - MU / rn) * r - np.dot(r, v) * v) / MU
    assert np.linalg.norm(e_vec) == pytest.approx(e, abs=1e-13)
    assert np.dot(e_vec, r) / (e * rn) == pytest.approx(np.cos(nu), abs=1e-12)
    assert rn == pytest.approx(a * (1 - e**2) / (1 + e * np.cos(nu)), rel=1e-14)


def test_roe_to_absolute_elements_inverts_damico_definitions() -> None:
    ref = np.array([A_M, U0_RAD, 1e-4, -2e-4, INC_RAD, RAAN_RAD])
    roe = initial_roe(0, 5, 3000.0)
    el = roe_to_absolute_elements(ref, roe)
    a, u, ex, ey, i, raan = el.T
    d_raan = raan - ref[5]
    back = A_M * np.stack((
        (a - ref[0]) / ref[0],
        (u - ref[1]) + d_raan * np.cos(ref[4]),
        ex - ref[2],
        ey - ref[3],
        i - ref[4],
        d_raan * np.sin(ref[4]),
    ), axis=-1)
    np.testing.assert_allclose(back, roe, rtol=0, atol=1e-6)


def test_absolute_initial_state_matches_linear_map_to_second_order() -> None:
    """Exact ROE -> ECI -> LVLH vs the linear map: residual O(|roe|^2 / a), quadratic in size."""
    ref = np.array([A_M, U0_RAD, 0.0, 0.0, INC_RAD, RAAN_RAD])
    r_ref, v_ref = qns_to_eci(ref)
    errors = []
    for scale in (400.0, 200.0):
        roe = initial_roe(1, 6, scale)
        r, v = qns_to_eci(roe_to_absolute_elements(ref, roe))
        pos, vel = eci_to_lvlh(r_ref, v_ref, r, v)
        pos_lin, vel_lin = roe_to_lvlh(roe, U0_RAD, N_RADPS)
        err = np.linalg.norm(pos - pos_lin, axis=1)
        bound = 2.0 * np.sum(roe**2, axis=1) / A_M
        assert np.all(err <= bound), (err, bound)
        assert np.all(np.linalg.norm(vel - vel_lin, axis=1) <= N_RADPS * bound)
        errors.append(err.max())
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)


# ------------------------------------------------------------------ propagation vs reference


CASES = {
    "j2_coast": dict(j2=True, drag=None, thrust_steps=0),
    "j2_thrust": dict(j2=True, drag=None, thrust_steps=5),
    "twobody_thrust": dict(j2=False, drag=None, thrust_steps=3),
    "j2_drag_thrust": dict(
        j2=True, drag={"bc_m2pkg": [0.005, 0.01, 0.02, 0.04], "bc_ref_m2pkg": 0.01}, thrust_steps=3
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_absolute_plant_matches_tight_integration_over_one_orbit(case: str) -> None:
    cfg = CASES[case]
    roe = initial_roe(2, 4, 800.0)
    plant = AbsoluteJ2Plant(A_M, INC_RAD, RAAN_RAD, U0_RAD, roe, j2=cfg["j2"], drag=cfg["drag"])
    r_ref, v_ref = plant.reference_eci()
    r_sc, v_sc = plant.spacecraft_eci()
    y = np.vstack((np.hstack((r_ref, v_ref)), np.hstack((r_sc, v_sc))))
    bc = None
    if cfg["drag"] is not None:
        bc = np.concatenate(([cfg["drag"]["bc_ref_m2pkg"]], cfg["drag"]["bc_m2pkg"]))
    rng = np.random.default_rng(5)
    n_steps = int(np.ceil(PERIOD_S / DT_S))
    check_every = 50  # coast segments between checks are integrated by one tight solve_ivp call
    worst, coasted = 0.0, 0
    for k in range(n_steps):
        thrusting = k < cfg["thrust_steps"]
        accel = rng.normal(0.0, 2e-3, (4, 3)) if thrusting else np.zeros((4, 3))
        plant.step(accel, DT_S)
        if thrusting:
            y = reference_step(y, accel, DT_S, cfg["j2"], bc)
        else:
            coasted += 1
        if thrusting or coasted == check_every or k == n_steps - 1:
            if coasted:
                y = reference_step(y, np.zeros((4, 3)), coasted * DT_S, cfg["j2"], bc)
                coasted = 0
            pos, _ = plant.relative_lvlh()
            worst = max(worst, np.abs(pos - relative_position(y)).max())
    assert plant.t_s == pytest.approx(n_steps * DT_S)
    assert worst < 1e-3, f"relative LVLH position error {worst} m"

    # Relative velocity: time derivative of the reference's LVLH position (4th-order central
    # difference of the tight integration), which includes the frame's J2 out-of-plane rotation.
    h = 2.0
    p = {
        d: relative_position(reference_step(y, np.zeros((4, 3)), d, cfg["j2"], bc))
        for d in (-2 * h, -h, h, 2 * h)
    }
    vel_fd = (p[-2 * h] - 8 * p[-h] + 8 * p[h] - p[2 * h]) / (12 * h)
    _, vel = plant.relative_lvlh()
    assert np.abs(vel - vel_fd).max() < 2e-6, np.abs(vel - vel_fd).max()


def test_j2_raan_precession_matches_secular_rate() -> None:
    plant = AbsoluteJ2Plant(A_M, INC_RAD, RAAN_RAD, U0_RAD, np.zeros((1, 6)))
    n_orbits = 5
    n_steps = 100 * n_orbits
    dt = n_orbits * PERIOD_S / n_steps  # ~57 s; end on a whole number of orbits (short-period terms cancel)
    for _ in range(n_steps):
        plant.step(None, dt)
    r, v = plant.reference_eci()
    h = np.cross(r, v)
    raan = np.arctan2(h[0], -h[1])
    rate = -1.5 * N_RADPS * J2_EGM * (RE / A_M) ** 2 * np.cos(INC_RAD)
    assert (raan - RAAN_RAD) == pytest.approx(rate * n_orbits * PERIOD_S, rel=0.01)


def test_two_body_plant_vs_linear_plant_is_second_order() -> None:
    """J2 off, 3 orbits: the only differences from the linear plant are second order in the ROE.

    Keplerian ROE (da, de, di) are constant and dl drifts at n_C - n_T = -3/2 n da + 15/8 n da^2,
    so the residual is the second-order remainder of the ROE -> rectilinear-LVLH map (curvature of
    the along-track arc, rho^2/(2a), and products like da*dl, de*dl), bounded by 2 |roe(t)|^2 / a
    with the current (drifted) ROE, plus the secular 15/8 n t a da^2. A first-order discrepancy
    (sign or map error) would scale linearly: halving the formation must quarter the residual.
    """
    worst = []
    for scale in (300.0, 150.0):
        roe = initial_roe(3, 6, scale)
        nonlin = AbsoluteJ2Plant(A_M, INC_RAD, RAAN_RAD, U0_RAD, roe, j2=False)
        lin = LinearRoePlant(A_M, INC_RAD, RAAN_RAD, U0_RAD, roe)
        worst_err = 0.0
        for k in range(int(3 * PERIOD_S / DT_S)):
            nonlin.step(None, DT_S)
            lin.step(None, DT_S)
            if k % 10 == 0:
                err = np.linalg.norm(nonlin.relative_lvlh()[0] - lin.relative_lvlh()[0], axis=1)
                bound = (2.0 * np.sum(lin.roe_m**2, axis=1)
                         + 15 / 8 * N_RADPS * lin.t_s * roe[:, 0] ** 2) / A_M
                assert np.all(err <= bound), (lin.t_s, err, bound)
                worst_err = max(worst_err, err.max())
        assert nonlin.reference_u() == pytest.approx(lin.reference_u(), abs=1e-9)
        worst.append(worst_err)
    assert worst[0] / worst[1] == pytest.approx(4.0, rel=0.05)
