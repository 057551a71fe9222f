"""Issue 16: controllers stepped as a batch (agent/controller.py `step_batch`) give each spacecraft
the command its own `step` gives, bit for bit: the paper-002 behavioural controller's vectorised
path on the observations of a real run and on random ones (disabled behaviours, no neighbours,
coincident spacecraft), and the default path (each `step` in turn) for a controller without one.
"""
from __future__ import annotations


import numpy as np
import pytest

from swarmhil.missions.p002_sabatini.fsw.sabatini import SabatiniController
from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, step_batch
from conftest import SCENARIOS
from swarmhil.deploy.scenario import load_scenario

SC = load_scenario(SCENARIOS / "sabatini-20.toml")
ORBIT = OrbitInfo(SC.orbit.semi_major_axis_m, SC.orbit.mean_motion_radps)


def _same(a: Command, b: Command) -> None:
    assert a.mode == b.mode
    assert np.asarray(a.accel_mps2).tobytes() == np.asarray(b.accel_mps2).tobytes(), (a.accel_mps2, b.accel_mps2)
    assert [(d.neighbour, d.behaviour, d.d_min_m) for d in a.decisions] == \
        [(d.neighbour, d.behaviour, d.d_min_m) for d in b.decisions]
    for d1, d2 in zip(a.decisions, b.decisions):
        assert d1.roe_rel_m.tobytes() == d2.roe_rel_m.tobytes() and d1.accel_mps2.tobytes() == d2.accel_mps2.tobytes()


def _check(controllers: list, observations: list[Observation]) -> CommandBatch:
    batch = ObservationBatch.of([c.sc_id if hasattr(c, "sc_id") else str(i) for i, c in enumerate(controllers)],
                                observations)
    cb = step_batch(controllers, batch)
    for i, (c, o) in enumerate(zip(controllers, observations)):
        one = c.step(o)
        _same(one, cb.command(i))
        assert cb.accel_mps2[i].tobytes() == np.asarray(one.accel_mps2, float).tobytes() and cb.modes[i] == one.mode
    return cb


@pytest.fixture(scope="module")
def captured(tmp_path_factory) -> list[list[Observation]]:
    """The observations of every spacecraft, step by step, of 20 minutes of sabatini-20 (in-process, one
    agent node per spacecraft)."""
    from swarmhil.deploy.launcher import run_in_process

    seen: list[tuple[str, Observation]] = []
    orig = SabatiniController.step

    def spy(self, obs):
        seen.append((self.sc_id, obs))
        return orig(self, obs)

    SabatiniController.step = spy
    try:
        run_in_process(SC.with_overrides(duration_s=1200.0), tmp_path_factory.mktemp("cap") / "r", "cap", opts={"batch": False})
    finally:
        SabatiniController.step = orig
    n = len(SC.ids)
    assert len(seen) == 120 * n
    return [[o for _s, o in seen[k:k + n]] for k in range(0, len(seen), n)]


def test_sabatini_batch_equals_each_step_on_a_run(captured) -> None:
    ctrls = [make_controller("sabatini", s, ORBIT, dict(SC.controller_params)) for s in SC.ids]
    behaviours = set()
    for obs in captured:
        cb = _check(ctrls, obs)
        behaviours |= {d.behaviour for i in range(len(obs)) for d in cb.command(i).decisions}
    assert {"collision_avoidance", "attraction"} <= behaviours and behaviours & {"alignment", "alignment_drift"}


def _random_obs(rng, n_nb: int, step: int) -> Observation:
    pos = rng.normal(0.0, 250.0, (n_nb, 3))
    vel = rng.normal(0.0, 0.3, (n_nb, 3))
    if n_nb > 1 and rng.random() < 0.2:
        pos[1], vel[1] = 0.0, 0.0  # coincident with the observer: zero de and di
    return Observation(step=step, t_s=10.0 * step, u_rad=0.37 * step, neighbour_ids=[f"n{k}" for k in range(n_nb)],
                       rel_position_m=pos, rel_velocity_mps=vel)


@pytest.mark.parametrize("disabled", [(), ("enable_collision_avoidance",), ("enable_alignment", "enable_attraction")])
def test_sabatini_batch_equals_each_step_on_random_observations(disabled) -> None:
    rng = np.random.default_rng(16)
    params = {**SC.controller_params, **{k: False for k in disabled}}
    ctrls = [make_controller("sabatini", f"s{i}", ORBIT, params) for i in range(12)]
    for step in range(40):
        obs = [_random_obs(rng, int(rng.integers(0, 9)), step) for _ in ctrls]
        _check(ctrls, obs)
    no_one = [_random_obs(rng, 0, 1) for _ in ctrls]
    assert _check(ctrls, no_one).modes == ["search"] * len(ctrls)


def test_mixed_parameters_and_controllers_without_a_batch_path() -> None:
    rng = np.random.default_rng(3)
    mixed = [make_controller("sabatini", "a", ORBIT, dict(SC.controller_params)),
             make_controller("sabatini", "b", ORBIT, {**SC.controller_params, "k_ecc": 1.5})]
    obs = [_random_obs(rng, 4, 2), _random_obs(rng, 3, 2)]
    _check(mixed, obs)  # one by one: each its own parameters
    drift = [make_controller("drift-null", f"d{i}", ORBIT, {"gain_per_s": 1e-4}) for i in range(3)]
    cb = _check(drift, [_random_obs(rng, k, 5) for k in (0, 2, 5)])  # the default: each `step` in turn
    assert cb.modes == ["search", "drift-null", "drift-null"]
    null = [make_controller("null", f"z{i}", ORBIT, {}) for i in range(3)]
    cb = _check(null, [_random_obs(rng, k, 5) for k in (0, 2, 5)])  # its own batch path
    assert cb.modes == ["coast"] * 3 and not cb.accel_mps2.any()


def test_observation_batch_round_trip() -> None:
    rng = np.random.default_rng(1)
    obs = [_random_obs(rng, k, 4) for k in (2, 0, 3)]
    b = ObservationBatch.of(["x", "y", "z"], obs)
    assert b.offsets.tolist() == [0, 2, 2, 5] and len(b) == 3
    for i, o in enumerate(obs):
        back = b.observation(i)
        assert back.neighbour_ids == o.neighbour_ids and (back.step, back.t_s, back.u_rad) == (o.step, o.t_s, o.u_rad)
        np.testing.assert_array_equal(back.rel_position_m, o.rel_position_m.reshape(-1, 3))
        np.testing.assert_array_equal(back.rel_velocity_mps, o.rel_velocity_mps.reshape(-1, 3))
