"""The configuration a run was made with, read from the recording itself (issue 11).

A recording carries its fully resolved configuration as MCAP metadata "swarmhil.config" (key
"json"; bus/recorder.py describe_run) and summary.json carries the same under "config". Reports and
the replay read it here, so they need nothing but the run directory (or the MCAP alone): no
scenario file, no repository checkout.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader

from swarmhil.plant.sensors import CameraGeometry


def config_from_mcap(mcap_path: str | Path) -> dict[str, Any] | None:
    """The resolved configuration in a recording's metadata, or None (older recording, or unreadable)."""
    try:
        with open(mcap_path, "rb") as f:
            for meta in make_reader(f).iter_metadata():
                if meta.name == "swarmhil.config":
                    return json.loads(meta.metadata["json"])
    except (OSError, McapError, EOFError, ValueError, KeyError):
        return None
    return None


def run_config(run_dir: str | Path) -> dict[str, Any] | None:
    """The resolved configuration of a run: the MCAP's metadata, else summary.json's "config"."""
    d = Path(run_dir)
    cfg = config_from_mcap(d / "run.mcap") if (d / "run.mcap").is_file() else None
    if cfg is not None:
        return cfg
    try:
        return json.loads((d / "summary.json").read_text()).get("config")
    except (OSError, ValueError):
        return None


def run_camera(run_dir: str | Path, summary: dict[str, Any] | None = None) -> CameraGeometry:
    """The camera of a run, from the run alone: the camera its metrics were computed for
    (summary.json["metrics"]["camera"]), else the configuration the recording carries, else (a sweep
    case recorded before that) the case's scenario_doc.json, else the paper's (500 m, 1080 px,
    f = 1000 px). Never a scenario file of the repository: the report needs no checkout."""
    d = Path(run_dir)
    cam = ((summary or {}).get("metrics") or {}).get("camera")
    if cam:
        return CameraGeometry(cam["detection_range_m"], int(cam["image_px"]), cam["focal_px"])
    recorded = camera_from_config(run_config(d))
    if recorded is not None:
        return recorded
    doc_path = d / "scenario_doc.json"
    if doc_path.is_file():
        c = json.loads(doc_path.read_text()).get("camera", {})
        return CameraGeometry(c.get("detection_range_m", 500.0), int(c.get("image_px", 1080)), c.get("focal_px", 1000.0))
    return CameraGeometry()


def camera_from_config(cfg: dict[str, Any] | None) -> CameraGeometry | None:
    c = (cfg or {}).get("camera")
    if not c:
        return None
    return CameraGeometry(float(c["detection_range_m"]), int(c["image_px"]), float(c["focal_px"]))
