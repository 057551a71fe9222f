"""The Propagator protocol and registry (plant/dynamics/propagator.py), and World holding one.

World's numbers must not change: its `linear` and `j2` runs are compared bit for bit with the
code path World used before it held a propagator (written out here: roe_linear.propagate_roe with
u = u0 + n k dt, and AbsoluteJ2Plant driven directly).
"""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.plant.dynamics import propagator as propagator_module
from swarmhil.plant.dynamics import roe_linear
from swarmhil.plant.dynamics.absolute_j2 import AbsoluteJ2Plant
from swarmhil.plant.dynamics.propagator import (
    Propagator,
    make_propagator,
    propagator_names,
    register_propagator,
)
from swarmhil.plant.world import World

A_M, INC, RAAN, U0 = 6878137.0, 1.7, 0.3, 0.5


def _world_run(fidelity: str, drag: dict | None = None, n_steps: int = 120, dt_s: float = 10.0):
    rng = np.random.default_rng(1)
    roe = rng.normal(0, 300, (5, 6))
    world = World([f"s{i}" for i in range(5)], roe, a_m=A_M, inc_rad=INC, raan_rad=RAAN, u0_rad=U0,
                  fidelity=fidelity, drag=drag)
    cmds = rng.normal(0, 5e-4, (n_steps, 5, 3))
    out = []
    for a in cmds:
        world.step(a, dt_s)
        out.append((*world.lvlh(), world.u_rad, world.roe_m(), world.t_s))
    return roe, cmds, out


def test_world_linear_is_bit_identical_to_the_direct_roe_model() -> None:
    roe, cmds, out = _world_run("linear")
    n = roe_linear.mean_motion(A_M)
    for k, a in enumerate(cmds):
        a = np.clip(a, -1e-3, 1e-3)
        roe = roe_linear.propagate_roe(roe, a, U0 + n * (k * 10.0), n, 10.0)
        u = U0 + n * ((k + 1) * 10.0)
        pos, vel = roe_linear.roe_to_lvlh(roe, u, n)
        w_pos, w_vel, w_u, w_roe, w_t = out[k]
        assert np.array_equal(w_pos, pos) and np.array_equal(w_vel, vel) and np.array_equal(w_roe, roe)
        assert w_u == u and w_t == (k + 1) * 10.0


@pytest.mark.parametrize("drag", [None, {"bc_m2pkg": [0.01, 0.02, 0.015, 0.01, 0.03]}], ids=["j2", "j2+drag"])
def test_world_j2_is_bit_identical_to_the_direct_absolute_plant(drag: dict | None) -> None:
    roe, cmds, out = _world_run("j2", drag, n_steps=40)
    plant = AbsoluteJ2Plant(A_M, INC, RAAN, U0, roe, j2=True, drag=drag)
    n = roe_linear.mean_motion(A_M)
    for k, a in enumerate(cmds):
        plant.step(np.clip(a, -1e-3, 1e-3), 10.0)
        pos, vel = plant.relative_lvlh()
        w_pos, w_vel, w_u, w_roe, _ = out[k]
        assert np.array_equal(w_pos, pos) and np.array_equal(w_vel, vel)
        assert w_u == plant.reference_u()
        assert np.array_equal(w_roe, roe_linear.lvlh_to_roe(pos, vel, plant.reference_u(), n))


def test_world_flies_cw_and_refuses_an_inertial_or_unknown_model() -> None:
    _, _, lin = _world_run("linear")
    _, _, hill = _world_run("cw")
    assert max(np.abs(a[0] - b[0]).max() for a, b in zip(lin, hill)) < 1e-6
    assert max(np.abs(a[3] - b[3]).max() for a, b in zip(lin, hill)) < 1e-6  # ROE through the linear map
    with pytest.raises(ValueError, match="unknown propagator 'sgp4'"):
        World(["a"], np.zeros((1, 6)), a_m=A_M, inc_rad=INC, raan_rad=RAAN, u0_rad=U0, fidelity="sgp4")
    with pytest.raises(ValueError, match="takes no argument"):
        World(["a"], np.zeros((1, 6)), a_m=A_M, inc_rad=INC, raan_rad=RAAN, u0_rad=U0, fidelity="inertial")
    with pytest.raises(ValueError, match="'linear' takes no argument drag"):
        World(["a"], np.zeros((1, 6)), a_m=A_M, inc_rad=INC, raan_rad=RAAN, u0_rad=U0, drag={"bc_m2pkg": 0.01})


def test_builtins_satisfy_the_protocol() -> None:
    common = {"a_m": A_M, "inc_rad": INC, "raan_rad": RAAN, "u0_rad": U0, "roe_m": np.ones((2, 6))}
    for name in ("linear", "j2", "cw"):
        prop = make_propagator(name, **common)
        assert isinstance(prop, Propagator) and prop.frame == "lvlh"
        prop.step(np.zeros((2, 3)), 5.0)
        prop.step(None, 5.0)
        pos, vel = prop.state()
        assert pos.shape == vel.shape == (2, 3) and prop.t_s == 10.0 and np.isfinite(prop.u_rad)


def test_a_mission_registers_its_own_propagator(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(propagator_module, "_REGISTRY", dict(propagator_module._REGISTRY))  # undone after the test

    @register_propagator("toy-drift")
    class ToyDrift:
        """Straight lines in the reference LVLH (a free-space toy)."""

        frame = "lvlh"

        def __init__(self, *, pos_m: np.ndarray, vel_mps: np.ndarray) -> None:
            self._p, self._v, self.t_s, self.u_rad = np.array(pos_m, float), np.array(vel_mps, float), 0.0, 0.0

        def step(self, accel_mps2, dt_s: float) -> None:
            a = 0.0 if accel_mps2 is None else accel_mps2
            self._p = self._p + self._v * dt_s + 0.5 * a * dt_s**2
            self._v = self._v + a * dt_s
            self.t_s += dt_s

        def state(self):
            return self._p.copy(), self._v.copy()

    assert "toy-drift" in propagator_names()
    prop = make_propagator("toy-drift", pos_m=np.zeros((1, 3)), vel_mps=np.ones((1, 3)))
    assert isinstance(prop, Propagator)
    prop.step(np.ones((1, 3)), 2.0)
    np.testing.assert_array_equal(prop.state()[0], [[4.0, 4.0, 4.0]])
    with pytest.raises(ValueError, match="already registered"):
        register_propagator("toy-drift")(lambda: None)
