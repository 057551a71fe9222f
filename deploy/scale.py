"""`swarmhil scale SCENARIO COUNT`: a large swarm from a scenario whose spacecraft a [dispersion] draws.

The scaled scenario is the same file with `[dispersion].count = COUNT` and `[run].name` given the
count (`sabatini-20` -> `sabatini-1000`); every other line, comments included, stays. The density
stays the paper's because the dispersion is per spacecraft (plant/dispersion.py `draw_roe`): each
spacecraft has its own along-track slot, `along_track_spacing_m` apart, so the string grows to
(COUNT - 1) x spacing along-track while a spacecraft's neighbourhood (the slots within the camera's
range, the same ROE sigmas) is the one of the paper's 20: `density` measures it, the mean number of
spacecraft each one sees at t = 0, for the base and the scaled scenario. The written file is loaded
back through the scenario schema (deploy/scenario.py), so a count outside 1..1000 or a draw that is
never weakly connected is the same error as in a hand-written file.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmhil.deploy.scenario import Scenario, ScenarioError, load_scenario
from swarmhil.plant.dynamics.roe_linear import roe_to_lvlh
from swarmhil.plant.sensors import CameraGeometry, visible_pairs

_TABLE = re.compile(r"^\s*\[([^\[\]]+)\]\s*(#.*)?$")


def _set_in_table(lines: list[str], table: str, key: str, value: str) -> bool:
    """Set `key = value` in the TOML table `table` of `lines` (in place): its line replaced (a trailing
    comment kept), or added as the table's first line. False if the table is not there."""
    start = next((i for i, s in enumerate(lines) if (m := _TABLE.match(s)) and m.group(1).strip() == table), None)
    if start is None:
        return False
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    pat = re.compile(rf"^(\s*){re.escape(key)}\s*=\s*(\"[^\"]*\"|[^#\s]+)(\s*#.*)?$")
    for i in range(start + 1, end):
        m = pat.match(lines[i])
        if m:
            lines[i] = f"{m.group(1)}{key} = {value}{m.group(3) or ''}"
            return True
    lines.insert(start + 1, f"{key} = {value}")
    return True


def scaled_name(name: str, count: int) -> str:
    """`sabatini-20` -> `sabatini-1000`, `sabatini-20-camera-exact` -> `sabatini-1000-camera-exact`
    (the first number that is a whole part of the name), else `NAME-COUNT`."""
    parts = name.split("-")
    for i, p in enumerate(parts):
        if p.isdigit():
            return "-".join([*parts[:i], str(count), *parts[i + 1:]])
    return f"{name}-{count}"


def scaled_text(text: str, count: int, name: str, source: str = "") -> str:
    """The scenario text with `[dispersion].count = count` and `[run].name = name` and a first comment line
    saying so (`source`: the base file's name); nothing else changed."""
    lines = text.splitlines()
    if not _set_in_table(lines, "dispersion", "count", str(int(count))):
        raise ScenarioError("the scenario has no [dispersion] table: only a drawn swarm scales (explicit "
                            "[[spacecraft]] tables are the spacecraft)")
    _set_in_table(lines, "run", "name", f'"{name}"')
    head = (f"# {source or 'The scenario'} at {int(count)} spacecraft (`swarmhil scale {source or 'SCENARIO'} {int(count)}`, "
            "docs/scaling.md): [dispersion].count and [run].name changed, nothing else.")
    return "\n".join([head, *lines]) + "\n"


@dataclass(frozen=True)
class Density:
    count: int
    along_track_span_m: float   # the initial string's extent along-track (max - min y)
    mean_seen: float            # spacecraft each one sees at t = 0 (the visibility rule), mean
    per_km: float               # spacecraft per km of the string


def density(sc: Scenario) -> Density:
    """The initial neighbourhood of a drawn swarm: how many spacecraft each one sees at t = 0 (the plant's
    visibility rule, plant/sensors.py) and the spacecraft per along-track km."""
    pos, _v = roe_to_lvlh(np.asarray(sc.roe_m, dtype=float), sc.orbit.u0_rad, sc.orbit.mean_motion_radps)
    cam = CameraGeometry(sc.camera["detection_range_m"], int(sc.camera["image_px"]), sc.camera["focal_px"])
    j, _k = visible_pairs(pos, cam)
    span = float(np.ptp(pos[:, 1])) if len(pos) else 0.0
    return Density(len(pos), span, len(j) / max(len(pos), 1), len(pos) / max(span / 1000.0, 1e-9))


def write_scaled(scenario: str | Path, count: int, out: str | Path | None = None) -> tuple[Path, Density, Density]:
    """Write the scaled scenario (default: beside SCENARIO, named after the new run name), load it back
    through the schema, and return (its path, the base's density, the scaled one's)."""
    src = Path(scenario)
    base = load_scenario(src)
    if not base.sections.get("_generated"):
        raise ScenarioError(f"{src.name}: no [dispersion] table draws its spacecraft: nothing to scale")
    name = scaled_name(base.name, count)
    path = Path(out) if out is not None else src.with_name(f"{name}.toml")
    path.write_text(scaled_text(src.read_text(encoding="utf-8"), count, name, src.name), encoding="utf-8")
    try:
        scaled = load_scenario(path)
    except ScenarioError:
        path.unlink(missing_ok=True)
        raise
    assert len(scaled.ids) == count and scaled.name == name, (len(scaled.ids), scaled.name)
    return path, density(base), density(scaled)
