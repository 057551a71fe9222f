"""Linear ROE plant (plant/dynamics/roe_linear.py) against Hill-Clohessy-Wiltshire physics.

References are written here independently of the module: the HCW closed-form state transition
(Clohessy & Wiltshire 1960; Vallado sec. 6.8 with x radial, y along-track, z cross-track) and a
tight numerical integration of the HCW ODE with thrust. Tolerances in metres and m/s.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from swarmhil.plant.dynamics.roe_linear import (
    LinearRoePlant,
    input_matrix,
    lvlh_to_roe,
    mean_motion,
    propagate_roe,
    roe_to_lvlh,
)

A_M = 6878137.0
MU = 3.986004418e14
N_RADPS = np.sqrt(MU / A_M**3)
INC_RAD = np.radians(97.4)


def hcw_closed_form(x0: np.ndarray, v0: np.ndarray, n: float, t: float) -> tuple[np.ndarray, np.ndarray]:
    """HCW state at t from (x0, v0), rows = spacecraft (Clohessy-Wiltshire solution)."""
    s, c = np.sin(n * t), np.cos(n * t)
    x, y, z = x0.T
    vx, vy, vz = v0.T
    pos = np.stack(
        (
            (4 - 3 * c) * x + s / n * vx + 2 / n * (1 - c) * vy,
            6 * (s - n * t) * x + y - 2 / n * (1 - c) * vx + (4 * s - 3 * n * t) / n * vy,
            c * z + s / n * vz,
        ),
        axis=-1,
    )
    vel = np.stack(
        (
            3 * n * s * x + c * vx + 2 * s * vy,
            -6 * n * (1 - c) * x - 2 * s * vx + (4 * c - 3) * vy,
            -n * s * z + c * vz,
        ),
        axis=-1,
    )
    return pos, vel


def hcw_rhs(n: float, accel: np.ndarray):
    """HCW ODE with constant LVLH acceleration, state (N*6,) = rows (x, y, z, vx, vy, vz)."""

    def f(_t: float, y: np.ndarray) -> np.ndarray:
        s = y.reshape(-1, 6)
        x, _, z, vx, vy, vz = s.T
        acc = np.stack(
            (3 * n**2 * x + 2 * n * vy, -2 * n * vx, -(n**2) * z), axis=-1
        ) + accel
        return np.hstack((s[:, 3:], acc)).ravel()

    return f


def random_roe(rng: np.random.Generator, n_sc: int, scale_m: float) -> np.ndarray:
    return rng.uniform(-1.0, 1.0, (n_sc, 6)) * scale_m


def test_mean_motion_is_keplerian() -> None:
    assert mean_motion(A_M) == pytest.approx(N_RADPS, rel=1e-15)
    assert 2 * np.pi / mean_motion(A_M) == pytest.approx(5676.98, abs=0.01)  # 500 km orbit period


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_linear_plant_matches_hcw_closed_form_over_24h(seed: int) -> None:
    rng = np.random.default_rng(seed)
    roe0 = random_roe(rng, 5, 500.0)
    u0 = rng.uniform(0, 2 * np.pi)
    pos0, vel0 = roe_to_lvlh(roe0, u0, N_RADPS)
    plant = LinearRoePlant(A_M, INC_RAD, 0.0, u0, roe0)
    dt_s, n_steps = 10.0, 8640
    worst_pos, worst_vel = 0.0, 0.0
    for k in range(1, n_steps + 1):
        plant.step(np.zeros((5, 3)), dt_s)
        if k % 20 == 0 or k == n_steps:
            pos, vel = plant.relative_lvlh()
            pos_ref, vel_ref = hcw_closed_form(pos0, vel0, N_RADPS, k * dt_s)
            worst_pos = max(worst_pos, np.abs(pos - pos_ref).max())
            worst_vel = max(worst_vel, np.abs(vel - vel_ref).max())
    assert plant.t_s == pytest.approx(86400.0)
    assert worst_pos < 1e-3, f"position error {worst_pos} m"
    assert worst_vel < 1e-6, f"velocity error {worst_vel} m/s"


def test_propagate_roe_with_thrust_matches_hcw_ode() -> None:
    rng = np.random.default_rng(7)
    roe = random_roe(rng, 4, 300.0)
    u = 1.1
    state = np.hstack(roe_to_lvlh(roe, u, N_RADPS))
    # A few ZOH steps with changing thrust, incl. a long one (n dt ~ 0.66 rad).
    for dt_s in (10.0, 10.0, 10.0, 37.0, 600.0, 10.0):
        accel = rng.normal(0.0, 1e-3, (4, 3))
        sol = solve_ivp(hcw_rhs(N_RADPS, accel), (0.0, dt_s), state.ravel(), method="DOP853",
                        rtol=1e-12, atol=1e-9)
        state = sol.y[:, -1].reshape(-1, 6)
        roe = propagate_roe(roe, accel, u, N_RADPS, dt_s)
        u += N_RADPS * dt_s
        pos, vel = roe_to_lvlh(roe, u, N_RADPS)
        assert np.abs(pos - state[:, :3]).max() < 1e-3
        assert np.abs(vel - state[:, 3:]).max() < 1e-6


def test_propagate_roe_uses_a_held_not_b_at_step_start() -> None:
    """Over a long step the exact ZOH differs from B(u0) dt: guards the closed-form integral."""
    accel = np.array([[0.0, 0.0, 1e-3]])
    dt_s = 0.25 * 2 * np.pi / N_RADPS  # quarter orbit
    roe = propagate_roe(np.zeros((1, 6)), accel, 0.0, N_RADPS, dt_s)
    # d(dix)/dt = cos(n t) f/n, d(diy)/dt = sin(n t) f/n -> dix = f/n^2, diy = f/n^2 after a quarter orbit.
    assert roe[0, 4] == pytest.approx(1e-3 / N_RADPS**2, rel=1e-12)
    assert roe[0, 5] == pytest.approx(1e-3 / N_RADPS**2, rel=1e-12)


def test_roe_lvlh_round_trip() -> None:
    rng = np.random.default_rng(3)
    for u in rng.uniform(-10, 10, 8):
        roe = random_roe(rng, 6, 2000.0)
        pos, vel = roe_to_lvlh(roe, u, N_RADPS)
        np.testing.assert_allclose(lvlh_to_roe(pos, vel, u, N_RADPS), roe, rtol=0, atol=1e-9)
        pos2, vel2 = rng.normal(0, 1000, (6, 3)), rng.normal(0, 1, (6, 3))
        back_pos, back_vel = roe_to_lvlh(lvlh_to_roe(pos2, vel2, u, N_RADPS), u, N_RADPS)
        np.testing.assert_allclose(back_pos, pos2, rtol=0, atol=1e-9)
        np.testing.assert_allclose(back_vel, vel2, rtol=0, atol=1e-12)


def test_input_matrix_is_a_pure_lvlh_acceleration() -> None:
    """d/dt of roe_to_lvlh under B(u) f must be zero in position and exactly f in velocity."""
    rng = np.random.default_rng(4)
    for u in rng.uniform(0, 2 * np.pi, 5):
        b = input_matrix(u, N_RADPS)
        pos, vel = roe_to_lvlh(b.T, u, N_RADPS)  # columns of B mapped through the (linear) map
        np.testing.assert_allclose(pos, 0.0, atol=1e-12)
        np.testing.assert_allclose(vel, np.eye(3), atol=1e-12)


def test_linear_plant_interface() -> None:
    plant = LinearRoePlant(A_M, INC_RAD, 0.0, 6.0, np.zeros((3, 6)))
    plant.step(None, 10.0)
    assert plant.reference_u() == pytest.approx((6.0 + 10.0 * N_RADPS) % (2 * np.pi))
    with pytest.raises(ValueError):
        plant.step(np.zeros((2, 3)), 10.0)


def _roe_to_lvlh_as_written(roe: np.ndarray, u: float, n: float) -> tuple[np.ndarray, np.ndarray]:
    """The map as it was written before issue 16 made it cheaper: the reference for bit equality."""
    c, s = np.cos(u), np.sin(u)
    da, dl, dex, dey, dix, diy = (roe[..., k] for k in range(6))
    pos = np.stack((da - dex * c - dey * s, dl + 2.0 * dex * s - 2.0 * dey * c, dix * s - diy * c), axis=-1)
    vel = n * np.stack((dex * s - dey * c, -1.5 * da + 2.0 * dex * c + 2.0 * dey * s, dix * c + diy * s), axis=-1)
    return pos, vel


def _with_specials(rng: np.random.Generator, shape: tuple[int, ...], low: int, high: int) -> np.ndarray:
    """Normal entries times 10^k (k in [low, high)), about 5 % of them one special value (0, -0, NaN, inf, subnormal)."""
    a = rng.normal(size=shape) * 10.0 ** rng.integers(low, high)
    a[rng.random(shape) < 0.05] = rng.choice([0.0, -0.0, np.nan, np.inf, 1e-310], size=1)
    return a


def _some_u(rng: np.random.Generator, high: float) -> float:
    """An argument of latitude in [-10, high), one time in ten 0, pi/2 or -0."""
    return float(rng.uniform(-10, high)) if rng.random() < 0.9 else float(rng.choice([0.0, np.pi / 2, -0.0]))


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")  # inf - inf on purpose
def test_roe_to_lvlh_is_bit_identical_to_the_formula_as_written() -> None:
    rng = np.random.default_rng(16)
    for shape in ((20, 6), (6,), (3, 5, 6), (0, 6)):
        for _ in range(200):
            roe = _with_specials(rng, shape, -3, 5)
            u = _some_u(rng, 1000)
            got, want = roe_to_lvlh(roe, u, N_RADPS), _roe_to_lvlh_as_written(roe, u, N_RADPS)
            assert got[0].shape == want[0].shape and got[1].shape == want[1].shape
            assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()


def _lvlh_to_roe_as_written(pos: np.ndarray, vel: np.ndarray, u: float, n: float) -> np.ndarray:
    """The inverse map as it was written before issue 29 made it cheaper: the reference for bit equality."""
    c, s = np.cos(u), np.sin(u)
    x, y, z = pos[..., 0], pos[..., 1], pos[..., 2]
    vx, vy, vz = (vel[..., k] / n for k in range(3))
    return np.stack((4.0 * x + 2.0 * vy, y - 2.0 * vx, 3.0 * c * x + s * vx + 2.0 * c * vy,
                     3.0 * s * x - c * vx + 2.0 * s * vy, s * z + c * vz, -c * z + s * vz), axis=-1)


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")  # inf - inf on purpose
def test_lvlh_to_roe_is_bit_identical_to_the_formula_as_written() -> None:
    rng = np.random.default_rng(29)
    for shape in ((20, 3), (3,), (3, 5, 3), (0, 3)):
        for _ in range(200):
            pos, vel, u = _with_specials(rng, shape, -3, 7), _with_specials(rng, shape, -5, 3), _some_u(rng, 1e5)
            got, want = lvlh_to_roe(pos, vel, u, N_RADPS), _lvlh_to_roe_as_written(pos, vel, u, N_RADPS)
            assert got.shape == want.shape and got.tobytes() == want.tobytes()
    for _ in range(200):  # strided rows (views of wider arrays), a numpy u and n
        both = _with_specials(rng, (6, 7), -3, 7)
        pos, vel, u = both[:, :3], both[:, 4:], np.float64(_some_u(rng, 1e5))
        got, want = lvlh_to_roe(pos, vel, u, np.float64(N_RADPS)), _lvlh_to_roe_as_written(pos, vel, u, N_RADPS)
        assert got.shape == want.shape and got.tobytes() == want.tobytes()
