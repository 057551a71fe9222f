"""Actuator limits (plant/dynamics/limits.py) against hand-computed cases."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.plant.dynamics.limits import force_to_accel, limit_command, limit_norm, limit_per_axis


def test_per_axis_clips_each_axis() -> None:
    u = np.array([[3.0, -4.0, 0.5], [0.1, 0.2, -0.3]])
    np.testing.assert_array_equal(limit_per_axis(u, 1.0), [[1.0, -1.0, 0.5], [0.1, 0.2, -0.3]])
    np.testing.assert_array_equal(limit_per_axis(u, np.array([2.0, 0.15])), [[2.0, -2.0, 0.5], [0.1, 0.15, -0.15]])
    per = np.array([[1.0, 5.0, 0.1], [1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(limit_per_axis(u, per), [[1.0, -4.0, 0.1], [0.1, 0.2, -0.3]])


def test_per_axis_equals_worlds_clip() -> None:
    """Bit-identical to plant/world.py's np.clip(a, -max, max)."""
    a = np.random.default_rng(0).normal(0, 2e-3, (50, 3))
    assert np.array_equal(limit_per_axis(a, 1e-3), np.clip(a, -1e-3, 1e-3))


def test_per_axis_equals_np_clip_bit_for_bit() -> None:
    """np.clip's bits (NaN, -0.0, +-inf, subnormals, a zero limit) for scalar, per-craft and per-axis
    limits, with a scalar limit checked without numpy (issue 16: once per step of a batch run)."""
    rng = np.random.default_rng(16)
    a = rng.normal(0, 2e-3, (400, 3)) * 10.0 ** rng.integers(-310, 3, (400, 3))
    a[rng.random((400, 3)) < 0.1] = rng.choice([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324], size=1)
    for m in (1e-3, 0.0, np.float64(2e-3).item(), rng.random(400) * 1e-3, rng.random((400, 3)) * 1e-3):
        mm = m[:, None] if isinstance(m, np.ndarray) and m.ndim == 1 else m
        want = np.clip(a, -mm, mm)
        got = limit_per_axis(a, m)
        assert got.tobytes() == want.tobytes()
    with pytest.raises(ValueError):
        limit_per_axis(a, float("nan"))
    with pytest.raises(ValueError):
        limit_per_axis(a, -1.0)


def test_norm_keeps_direction_and_caps_magnitude() -> None:
    u = np.array([[3.0, -4.0, 0.0], [0.1, 0.2, -0.2], [0.0, 0.0, 0.0]])
    out = limit_norm(u, 1.0)
    np.testing.assert_allclose(out[0], [0.6, -0.8, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(out[1:], u[1:])  # under the limit (|u| = 0.3) and zero untouched
    out = limit_norm(u, np.array([10.0, 0.15, 1.0]))
    np.testing.assert_array_equal(out[0], u[0])
    np.testing.assert_allclose(np.linalg.norm(out[1]), 0.15, rtol=1e-15)
    np.testing.assert_allclose(out[1] / 0.15, u[1] / 0.3, rtol=1e-15)


def test_by_name_and_errors() -> None:
    u = np.array([[2.0, 0.0, 2.0]])
    np.testing.assert_array_equal(limit_command(u, 1.0, "per_axis"), [[1.0, 0.0, 1.0]])
    np.testing.assert_allclose(limit_command(u, 1.0, "norm"), [[2**-0.5, 0.0, 2**-0.5]], rtol=1e-15)
    with pytest.raises(ValueError, match="unknown actuator limit mode 'box'"):
        limit_command(u, 1.0, "box")
    with pytest.raises(ValueError, match=">= 0"):
        limit_norm(u, -1.0)
    with pytest.raises(ValueError, match="one value per craft"):
        limit_norm(u, np.ones((1, 3)))


def test_force_to_accel() -> None:
    f = np.array([[10.0, 0.0, -5.0], [1.0, 1.0, 1.0]])
    np.testing.assert_array_equal(force_to_accel(f, np.array([100.0, 2.0])), [[0.1, 0.0, -0.05], [0.5, 0.5, 0.5]])
    np.testing.assert_array_equal(force_to_accel(f, 10.0), f / 10.0)
    with pytest.raises(ValueError, match="mass_kg must be > 0"):
        force_to_accel(f, np.array([1.0, 0.0]))


def test_world_step_accounts_delta_v_of_the_limited_command() -> None:
    """World.step itself (not numpy against numpy): delta-v += |clip(a)| dt per live craft, checked
    against hand-computed values (3-4-5 triangles, sqrt(2) and sqrt(3) of a saturated command, a
    dead craft coasting) and, bit for bit, against the same sum done in plain Python floats
    (math.sqrt of x*x + y*y + z*z: correctly rounded operations in the order numpy reduces 3 values,
    so the same bits on any CPU)."""
    import math

    from swarmhil.plant.world import World

    cmds = np.array([
        [3e-4, 4e-4, 0.0],      # |a| = 5e-4, under the 1e-3 limit on every axis
        [0.0, -6e-4, 8e-4],     # |a| = 1e-3
        [5e-3, -2e-3, 0.0],     # both axes clip to 1e-3: sqrt(2) e-3, not |(5, -2)| e-3
        [-9.0, 9.0, 9.0],       # all three clip: sqrt(3) e-3
        [0.0, 0.0, 0.0],        # no thrust, no delta-v
        [1e-3, 1e-3, 1e-3],     # dead below: coasts, no delta-v although it asks for thrust
    ])
    n = len(cmds)
    w = World([f"sc{i}" for i in range(n)], np.zeros((n, 6)), a_m=6_878_137.0, inc_rad=1.7, raan_rad=0.0,
              u0_rad=0.0, max_accel_mps2=1e-3)
    w.alive[5] = False
    dt, steps = 10.0, 7
    for _ in range(steps):
        w.step(cmds, dt)
    per_step = np.array([5e-4, 1e-3, math.sqrt(2) * 1e-3, math.sqrt(3) * 1e-3, 0.0, 0.0])
    np.testing.assert_allclose(w.delta_v_mps, steps * dt * per_step, rtol=1e-14, atol=0.0)
    assert w.delta_v_mps[4] == 0.0 and w.delta_v_mps[5] == 0.0
    np.testing.assert_array_equal(w.last_accel_mps2[2:4], [[1e-3, -1e-3, 0.0], [-1e-3, 1e-3, 1e-3]])
    np.testing.assert_array_equal(w.last_accel_mps2[5], [0.0, 0.0, 0.0])
    # random commands, half of them saturating, some craft dead: the same arithmetic in Python floats
    rng = np.random.default_rng(24)
    w = World([f"sc{i}" for i in range(40)], np.zeros((40, 6)), a_m=6_878_137.0, inc_rad=1.7, raan_rad=0.0,
              u0_rad=0.0, max_accel_mps2=1e-3)
    w.alive[rng.random(40) < 0.2] = False
    want = [0.0] * 40
    for _ in range(5):
        cmd = rng.normal(0.0, 1e-3, (40, 3))
        w.step(cmd, 3.0)
        for i in range(40):
            if w.alive[i]:
                x, y, z = (min(max(float(c), -1e-3), 1e-3) for c in cmd[i])
                want[i] += math.sqrt(x * x + y * y + z * z) * 3.0
    assert w.delta_v_mps.tolist() == want


@pytest.mark.parametrize("modes,same_max", [(["norm", "per_axis"] * 6, False), (["norm"] * 12, False),
                                            (["norm"] * 12, True), (["per_axis"] * 12, True)],
                         ids=["mixed", "norm", "norm-one-max", "per-axis-one-max"])
def test_world_limit_equals_the_per_craft_loop_bit_for_bit(modes: list[str], same_max: bool) -> None:
    """MissionWorld.limit limits each limit mode's spacecraft in one call, and all of them in one call
    on the whole array when they share one mode (issue 29): the bits of the per-craft loop it replaced,
    `f(a[i:i+1], max_i)` (NaN, -0.0, +-inf, subnormals; norm and per axis)."""
    from swarmhil.plant.mission_world import MissionWorld

    rng = np.random.default_rng(29)
    n = len(modes)
    world = MissionWorld.__new__(MissionWorld)
    world.limit_mode, world.alive = modes, np.ones(n, dtype=bool)
    world.max_accel_mps2 = np.full(n, 3e-3) if same_max else rng.random(n) * 1e-2
    world._plan_limits()
    assert (world._limit_all is None) == (len(set(modes)) > 1)
    for _ in range(200):
        a = rng.normal(0, 2e-2, (n, 3)) * 10.0 ** rng.integers(-310, 2, (n, 3))
        a[rng.random((n, 3)) < 0.1] = rng.choice([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324], size=1)
        want = a.copy()
        for i, m in enumerate(modes):
            f = limit_norm if m == "norm" else limit_per_axis
            want[i] = f(a[i:i + 1], float(world.max_accel_mps2[i]))[0]
        assert world.limit(a).tobytes() == want.tobytes()
        assert world.limit(np.hstack((a, a))[:, :3]).tobytes() == want.tobytes()  # (a strided view: the plant's held[:, :3])


@pytest.mark.filterwarnings("ignore:overflow:RuntimeWarning")  # squares beyond 1e308 on purpose
def test_row_norm_is_numpys_norm_bit_for_bit() -> None:
    """limits.row_norm is np.linalg.norm(u, axis=-1), bit for bit (NaN, -0.0, +-inf, subnormals, strided views)."""
    from swarmhil.plant.dynamics.limits import row_norm

    rng = np.random.default_rng(29)
    for shape in ((12, 3), (3,), (4, 5, 3), (0, 3)):
        for _ in range(100):
            u = rng.normal(size=shape) * 10.0 ** rng.integers(-310, 300)
            u[rng.random(shape) < 0.1] = rng.choice([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324], size=1)
            for v in (u, np.concatenate((u, u), axis=-1)[..., 1:4]):
                assert row_norm(v).tobytes() == np.linalg.norm(v, axis=-1).tobytes()


def test_limit_norm_is_the_scaled_product_byte_for_byte() -> None:
    """limit_norm (issue 29: `u * 1.0` when no row is over its limit) equals the scaled product it
    always computed, u * scale with scale = max/|u| over the limit and 1 elsewhere, byte for byte:
    rows under and over, NaN, ±inf, -0.0 and subnormals, a scalar and a per-craft limit."""
    from swarmhil.plant.dynamics.limits import limit_norm_rows, row_norm

    def before(u: np.ndarray, m: float | np.ndarray) -> np.ndarray:
        norm = row_norm(u)
        over = norm > m
        scale = np.ones_like(norm)
        np.divide(m, norm, out=scale, where=over)
        return u * scale[..., None]

    rng = np.random.default_rng(29)
    specials = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, -1e-310])
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(500):
            n = int(rng.integers(0, 8))
            u = rng.normal(0, 1, (n, 3)) * 10.0 ** rng.integers(-6, 2, (n, 1))
            u[rng.random((n, 3)) < 0.1] = rng.choice(specials)
            for m in (5e-3, 1e3, float(rng.uniform(0, 2)), rng.uniform(0, 2, n)):
                got, want = limit_norm(u, m), before(u, m)
                assert got.shape == want.shape and got.tobytes() == want.tobytes()
                again, norms = limit_norm_rows(u, m)  # the norms of the limited rows, when none was over
                assert again.tobytes() == want.tobytes()
                assert norms is None or norms.tobytes() == row_norm(want).tobytes()
                assert norms is not None or (row_norm(u) > m).any()
