"""Scenario validation: errors that name the bad field; generated and explicit initial conditions."""
from __future__ import annotations

import tomllib

import numpy as np
import pytest

from conftest import SCENARIOS
from swarmhil.deploy.scenario import ScenarioError, load_scenario, parse_scenario
from swarmhil.plant.dynamics.roe_linear import roe_to_lvlh
from swarmhil.plant.sensors import CameraGeometry, visibility_matrix, weakly_connected


def base() -> dict:
    return {"run": {"name": "t", "duration_s": 100.0}, "spacecraft": [{"id": "a", "roe_m": [0, 0, 0, 0, 0, 0]}]}


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d["run"].update(duration_s=-5), "[run].duration_s"),
    (lambda d: d["run"].update(step_s="ten"), "[run].step_s"),
    (lambda d: d["run"].update(mode="fast"), "[run].mode"),
    (lambda d: d.update(orbit={"semi_major_axis_m": 100.0}), "[orbit].semi_major_axis_m"),
    (lambda d: d.update(orbit={"eccentricity": 0.1}), "[orbit].eccentricity"),
    (lambda d: d.update(controller={"name": "nope"}), "[controller].name"),
    (lambda d: d.update(plant={"fidelity": "n-body"}), "[plant].fidelity"),
    (lambda d: d["spacecraft"][0].update(roe_m=[1, 2, 3]), "[[spacecraft]][0].roe_m"),
    (lambda d: d["spacecraft"][0].update(roe_m=[1, 2, 3, 4, 5, float("nan")]), "[[spacecraft]][0].roe_m[5]"),
    (lambda d: d["spacecraft"][0].update(id="a/b"), "[[spacecraft]][0].id"),
    (lambda d: d["spacecraft"].append({"id": "a", "roe_m": [0] * 6}), "[[spacecraft]][1].id"),
    (lambda d: d.update(bogus={}), "[bogus]"),
    (lambda d: d.update(sensing={"kind": "scene"}, nav={"navigator": "kalman"}), "[nav].navigator"),
    (lambda d: d.update(sensing={"kind": "scene"}, nav={"params": {"accel_sigmaa_mps2": 1e-6}}), "[nav.params].accel_sigmaa_mps2"),
    (lambda d: d.update(sensing={"kind": "scene"}, nav={"params": {"accel_sigma_mps2": float("nan")}}), "[nav.params].accel_sigma_mps2"),
    (lambda d: d.update(sensing={"kind": "scene"}, nav={"params": {"confirm_hits": 2.5}}), "[nav.params].confirm_hits"),
    (lambda d: d.update(sensing={"kind": "scene"}, nav={"navigator": "rough", "params": {"gate_chi2": 9.0}}), "[nav.params].gate_chi2"),
])
def test_errors_name_the_field(mutate, field: str) -> None:
    d = base()
    mutate(d)
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(d, "x.toml")
    assert field in str(exc.value) and str(exc.value).startswith("x.toml:")


def test_broken_toml_file(tmp_path) -> None:
    p = tmp_path / "broken.toml"
    p.write_text("[run\nname=")
    with pytest.raises(ScenarioError, match="broken.toml: not valid TOML"):
        load_scenario(p)
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "missing.toml")


def test_shipped_scenarios_parse() -> None:
    for path in sorted(SCENARIOS.glob("*.toml")):
        sc = load_scenario(path)
        assert len(sc.ids) == sc.roe_m.shape[0] > 0, path.name


def test_drift20_generator_is_seeded_and_weakly_connected() -> None:
    a = load_scenario(SCENARIOS / "drift-20.toml")
    b = load_scenario(SCENARIOS / "drift-20.toml")
    assert np.array_equal(a.roe_m, b.roe_m) and len(a.ids) == 20
    pos, _ = roe_to_lvlh(a.roe_m, a.orbit.u0_rad, a.orbit.mean_motion_radps)
    assert weakly_connected(visibility_matrix(pos, CameraGeometry()))
    c = a.with_overrides(seed=a.seed + 1)
    assert not np.array_equal(a.roe_m, c.roe_m)


def test_explicit_spacecraft_replace_generated() -> None:
    doc = tomllib.loads((SCENARIOS / "drift-20.toml").read_text())
    doc["spacecraft"] = [{"id": "x1", "roe_m": [1, 2, 3, 4, 5, 6]}, {"id": "x2", "roe_m": [0, 100, 0, 0, 0, 0]}]
    sc = parse_scenario(doc, "d.toml")
    assert sc.ids == ["x1", "x2"] and sc.roe_m[0].tolist() == [1, 2, 3, 4, 5, 6]
