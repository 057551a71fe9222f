"""Runs that claims' sources are made of: an in-process batch run of a shipped scenario, its truth.

Nothing here computes a metric: the metrics are dashboards/metrics.py's and the mission reports'
(the sources call them). These helpers only run a scenario the way the docs' commands do, without
a recording on disk that outlives the call.
"""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

SCENARIOS = Path(__file__).resolve().parent.parent / "deploy" / "scenarios"


def scenario(name: str, sets: tuple[str, ...] = (), seed: int | None = None,
             duration_s: float | None = None) -> Any:
    """A shipped scenario (deploy/scenarios/NAME.toml) with `--set` overrides, a seed and a duration."""
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(SCENARIOS / f"{name}.toml", list(sets))
    return sc.with_overrides(duration_s=duration_s, seed=seed)


def run_truth(sc: Any) -> Any:
    """`swarmhil run SCENARIO --in-process --record truth` (batch mode where allowed): the truth arrays."""
    from swarmhil.deploy.launcher import run_in_process

    from swarmhil.dashboards.truth_io import read_truth

    with tempfile.TemporaryDirectory(prefix="claims-") as d:
        res = run_in_process(sc, Path(d), f"claims-{sc.name}", record="truth", keep_truth=True)
        if res.truth is not None:
            return res.truth
        return read_truth(Path(d) / "run.mcap")  # worlds that keep no truth arrays (e.g. CW): read it back


def camera_of(sc: Any) -> Any:
    """The scenario's camera geometry (the plant's visibility rule)."""
    from swarmhil.plant.sensors import CameraGeometry

    c = sc.camera
    return CameraGeometry(c["detection_range_m"], c["image_px"], c["focal_px"])
