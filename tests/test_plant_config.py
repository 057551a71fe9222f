"""The plant's typed configuration (plant/config.py, built by deploy/scenario.py `plant_config`): the
values of the scenario, frozen. That the truth built from it is unchanged is
tests/test_truth_checksums.py's and the missions' stack tests' job."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import SCENARIOS
from swarmhil.deploy.scenario import load_scenario, plant_config
from swarmhil.plant.config import PlantConfig


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_plant_config_holds_the_scenarios_values(path) -> None:
    sc = load_scenario(path)
    cfg = plant_config(sc)
    assert isinstance(cfg, PlantConfig)
    assert cfg.ids == tuple(sc.ids) and cfg.steps == sc.steps and cfg.step_s == sc.step_s and cfg.seed == sc.seed
    assert (cfg.mode, cfg.speed, cfg.stall_timeout_s) == (sc.mode, sc.speed, sc.stall_timeout_s)
    o = sc.orbit
    assert (cfg.orbit.semi_major_axis_m, cfg.orbit.inclination_rad, cfg.orbit.raan_rad, cfg.orbit.u0_rad,
            cfg.orbit.eccentricity, cfg.orbit.argp_rad, cfg.orbit.mean_motion_radps) == (
        o.semi_major_axis_m, o.inclination_rad, o.raan_rad, o.u0_rad, o.eccentricity, o.argp_rad, o.mean_motion_radps)
    assert np.array_equal(cfg.roe_m, sc.roe_m) and cfg.roe_m is not sc.roe_m
    assert cfg.spacecraft == tuple(sc.spacecraft) and cfg.bodies == tuple(sc.bodies) and cfg.faults == tuple(sc.faults)
    assert (cfg.fidelity, cfg.max_accel_mps2, cfg.actuator_limit, cfg.contact) == (
        sc.fidelity, sc.max_accel_mps2, sc.actuator_limit, sc.contact)
    assert dict(cfg.camera) == sc.camera and dict(cfg.plant_options) == sc.plant_options
    assert cfg.sensing["kind"] == sc.sensing["kind"]
    for sid in sc.ids:
        name, params = cfg.controller_of(sid)
        assert name == sc.controller_of(sid)[0] and sorted(params) == sorted(sc.controller_of(sid)[1])


def test_plant_config_is_frozen() -> None:
    sc = load_scenario(SCENARIOS / "servicing-6.toml", sets=["controller.params.b.s4=0"])  # a nested table
    cfg = plant_config(sc)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.step_s = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        cfg.sensing["kind"] = "ideal"  # type: ignore[index]
    with pytest.raises(ValueError, match="read-only"):
        cfg.roe_m[0, 0] = 1.0
    params = cfg.controller_of(sc.ids[0])[1]
    assert params["b"] == {"s4": 0}
    with pytest.raises(TypeError):
        params["b"]["s4"] = 1  # type: ignore[index]
    # a later change of the scenario does not reach the plant's copy
    before = cfg.roe_m.copy()
    sc.roe_m[:] = 7.0
    assert np.array_equal(cfg.roe_m, before)


def test_the_plant_builds_its_world_by_fidelity() -> None:
    """Issue 25: the world is looked up by fidelity (plant/worlds.py), no branch of PlantNode names
    paper 002's truth model; an unregistered fidelity is one precise error."""
    import plant.node  # noqa: F401  (imports both world modules, as the plant process does)
    from swarmhil.plant.mission_world import MissionWorld
    from swarmhil.plant.world import World
    from swarmhil.plant.worlds import make_world, world_fidelities

    assert world_fidelities() == ["cw", "inertial", "j2", "linear"]
    s20 = plant_config(load_scenario(SCENARIOS / "sabatini-20.toml"))
    w = make_world(s20)
    assert type(w) is World and w.fidelity == "linear" and w.ids == list(s20.ids)
    assert np.array_equal(w.roe_m(), np.asarray(s20.roe_m))
    assert type(make_world(plant_config(load_scenario(SCENARIOS / "servicing-6.toml")))) is MissionWorld
    with pytest.raises(ValueError, match="no plant world flies fidelity 'nope'; known: \\['cw', 'inertial', 'j2', 'linear'\\]"):
        make_world(dataclasses.replace(s20, fidelity="nope"))
