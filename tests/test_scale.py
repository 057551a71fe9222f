"""`swarmhil scale SCENARIO COUNT` (deploy/scale.py): a drawn swarm at COUNT spacecraft, the same file
but for the count and the run name, loaded back through the schema, at the base's density."""
from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import SCENARIOS
from swarmhil.deploy.cli import main
from swarmhil.deploy.scale import density, scaled_name, scaled_text, write_scaled
from swarmhil.deploy.scenario import ScenarioError, load_scenario


def test_scaled_scenario_changes_the_count_and_the_name_only(tmp_path: Path) -> None:
    src = SCENARIOS / "sabatini-20-camera-exact.toml"
    path, base, scaled = write_scaled(src, 300, tmp_path / "big.toml")
    old, new = src.read_text().splitlines(), path.read_text().splitlines()
    assert new[0].startswith("# sabatini-20-camera-exact.toml at 300 spacecraft") and len(new) == len(old) + 1
    changed = [(a, b) for a, b in zip(old, new[1:]) if a != b]
    assert changed == [('name = "sabatini-20-camera-exact"', 'name = "sabatini-300-camera-exact"'), ("count = 20", "count = 300")]
    sc = load_scenario(path)
    assert len(sc.ids) == 300 and sc.ids[0] == "sc001" and sc.sensing["kind"] == "scene"
    # the density is the paper's: spacecraft per along-track km and neighbours seen at t = 0
    assert base.count == 20 and scaled.count == 300
    assert scaled.along_track_span_m > 14 * base.along_track_span_m
    assert abs(scaled.per_km / base.per_km - 1.0) < 0.1
    assert abs(scaled.mean_seen / base.mean_seen - 1.0) < 0.3 and scaled.mean_seen > 1.0
    assert density(sc) == scaled


def test_scale_errors_are_the_schema_s(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"\[dispersion\]\.count must be an integer in 1\.\.1000 \(got 1001\)"):
        write_scaled(SCENARIOS / "sabatini-20.toml", 1001, tmp_path / "x.toml")
    assert not (tmp_path / "x.toml").exists()
    with pytest.raises(ScenarioError, match="no \\[dispersion\\] table"):
        write_scaled(SCENARIOS / "sabatini-20-explicit.toml", 100, tmp_path / "y.toml")
    with pytest.raises(ScenarioError, match="no \\[dispersion\\] table"):
        scaled_text("[run]\nname = \"a\"\n", 5, "a-5")


def test_scaled_names_and_the_command(tmp_path: Path) -> None:
    assert scaled_name("sabatini-20", 1000) == "sabatini-1000"
    assert scaled_name("sabatini-20-camera-exact", 100) == "sabatini-100-camera-exact"
    assert scaled_name("drift", 50) == "drift-50"
    res = CliRunner().invoke(main, ["scale", str(SCENARIOS / "sabatini-20.toml"), "100", "--out", str(tmp_path / "s.toml")])
    assert res.exit_code == 0, res.output
    assert "100 spacecraft" in res.output and "per km" in res.output and load_scenario(tmp_path / "s.toml").name == "sabatini-100"
    res = CliRunner().invoke(main, ["scale", str(SCENARIOS / "sabatini-20.toml"), "0", "--out", str(tmp_path / "z.toml")])
    assert res.exit_code == 2 and "[dispersion].count must be an integer" in res.output
