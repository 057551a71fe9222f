"""plant/mission_world.py: `[plant].command_frame = "eci"` (commands in ECI axes, applied as given;
the recorded accel stays in the scenario frame) and an eccentric `[orbit]` (eccentricity, argp_deg)
as the inertial reference; both validated by deploy/scenario.py. Added flying paper 004, whose flight
software computes in inertial axes around a defunct craft on a 300 x 700 km orbit."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from swarmhil.deploy.scenario import ScenarioError, parse_scenario, plant_config
from swarmhil.plant.dynamics.absolute_j2 import kepler_to_eci
from swarmhil.plant.dynamics.constants import MU_EARTH_M3PS2
from swarmhil.plant.dynamics.frames import lvlh_basis
from swarmhil.plant.mission_world import MissionWorld

DOC = {
    "run": {"duration_s": 10.0, "step_s": 0.1},
    "orbit": {"semi_major_axis_m": 6878137.0, "inclination_deg": 30.0},
    "plant": {"fidelity": "inertial", "frame_origin": "chief", "j2": True, "atmospheric_drag": False},
    "spacecraft": [
        {"id": "chief", "position_m": [0.0, 0.0, 0.0], "max_accel_mps2": 100.0},
        {"id": "deputy", "position_m": [300.0, 1000.0, -200.0], "velocity_mps": [1.0, -2.0, 0.5],
         "max_accel_mps2": 100.0},
    ],
}


def _world(**plant: object) -> MissionWorld:
    doc = copy.deepcopy(DOC)
    doc["plant"].update(plant)
    return MissionWorld(plant_config(parse_scenario(doc, "command-frame-test")))


def test_eci_commands_are_applied_unrotated_and_recorded_in_the_scenario_frame() -> None:
    eci, lvlh = _world(command_frame="eci"), _world()
    ids, r, v = eci.eci()
    assert ids == ["chief", "deputy"]
    rot = lvlh_basis(r[0], v[0])                      # ECI -> the chief's LVLH (the scenario frame)
    a_eci = np.array([[0.0, 0.0, 0.0], [0.3, -0.7, 1.1]])
    eci.step(a_eci, 0.1)
    lvlh.step(a_eci @ rot.T, 0.1)                     # the same acceleration, given in LVLH
    _, r1, v1 = eci.eci()
    _, r2, v2 = lvlh.eci()
    assert np.abs(r1 - r2).max() < 1e-9 and np.abs(v1 - v2).max() < 1e-11
    np.testing.assert_allclose(eci.last_accel_mps2, lvlh.last_accel_mps2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(eci.delta_v_mps, lvlh.delta_v_mps, rtol=1e-15)
    # and it is really ECI: the deputy's ECI velocity changed by a dt (plus gravity, same in both)
    coast = _world(command_frame="eci")
    coast.step(np.zeros((2, 3)), 0.1)
    np.testing.assert_allclose(v1[1] - coast.eci()[2][1], a_eci[1] * 0.1, rtol=0, atol=1e-8)  # J2 gradient over 0.4 mm


def test_command_frame_is_validated() -> None:
    with pytest.raises(ScenarioError, match="command_frame"):
        parse_scenario({**DOC, "plant": {**DOC["plant"], "command_frame": "body"}}, "t")
    cw = {**DOC, "plant": {"fidelity": "cw", "command_frame": "eci"}}
    with pytest.raises(ScenarioError, match="need fidelity = 'inertial'"):
        parse_scenario(cw, "t")
    parse_scenario({**DOC, "plant": {"fidelity": "cw", "command_frame": "lvlh"}}, "t")  # the default: any
    assert "command_frame" not in parse_scenario(DOC, "t").plant_options             # resolved configs unchanged


def test_eccentric_reference_orbit() -> None:
    a, e, argp, u0 = 6878137.0, 0.02907764122755915, 40.0, 50.0
    doc = copy.deepcopy(DOC)
    doc["orbit"].update(eccentricity=e, argp_deg=argp, u0_deg=u0, raan_deg=10.0)
    sc = parse_scenario(doc, "t")
    assert sc.resolved()["orbit"]["eccentricity"] == e and sc.resolved()["orbit"]["argp_deg"] == pytest.approx(argp)
    _, r, v = MissionWorld(plant_config(sc)).eci()
    want_r, want_v = kepler_to_eci(a, e, np.radians(30.0), np.radians(10.0), np.radians(argp), np.radians(u0 - argp))
    assert np.abs(r[0] - want_r).max() < 1e-6 and np.abs(v[0] - want_v).max() < 1e-9
    energy = 0.5 * v[0] @ v[0] - MU_EARTH_M3PS2 / np.linalg.norm(r[0])
    assert -MU_EARTH_M3PS2 / (2 * energy) == pytest.approx(a, rel=1e-12)
    assert "eccentricity" not in parse_scenario(DOC, "t").resolved()["orbit"]       # circular: as before
    for bad, match in (({"eccentricity": 0.95}, "eccentricity"), ({"eccentricity": 0.2}, "periapsis")):
        d = copy.deepcopy(DOC)
        d["orbit"].update(bad)
        with pytest.raises(ScenarioError, match=match):
            parse_scenario(d, "t")
    d = copy.deepcopy(DOC)
    d["orbit"]["eccentricity"] = 0.01
    d["plant"] = {"fidelity": "cw"}
    with pytest.raises(ScenarioError, match="inertial"):
        parse_scenario(d, "t")
