"""A run's swarm metrics written beside its recording: summary.json["metrics"] and
metrics_series.npz (reading and analysis only: no figures, no pages).

`write_report` (dashboards/report.py) and the navigation comparison (dashboards/navreport/) both
start here; a campaign's batch run hands in the truth arrays it already holds (`write_metrics`).
The camera of a run is read from the run itself (dashboards/run_config.py `run_camera`).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.metrics import SwarmMetrics, compute_metrics
from swarmhil.dashboards.run_config import run_camera
from swarmhil.dashboards.truth_io import TruthArrays, read_truth
from swarmhil.plant.sensors import CameraGeometry

SERIES = "metrics_series.npz"  # per-step series a sweep report overlays


def read_summary(run_dir: Path) -> dict[str, Any]:
    """run_dir/summary.json, or {} when there is none."""
    spath = run_dir / "summary.json"
    return json.loads(spath.read_text()) if spath.is_file() else {}


def write_metrics(run_dir: str | Path, truth: TruthArrays, cam: CameraGeometry,
                  steady_from_s: float | None = None) -> Path:
    """What `write_report(..., figures=False)` writes (the metrics into run_dir/summary.json and
    run_dir/metrics_series.npz), from truth arrays the caller already holds (issue 16: a campaign's
    batch run keeps them, deploy/batch.TruthLog) instead of reading run.mcap back."""
    run_dir = Path(run_dir)
    store_metrics(run_dir, read_summary(run_dir), truth, cam, steady_from_s)
    return run_dir / "summary.json"


def store_metrics(run_dir: Path, summary: dict[str, Any], truth: TruthArrays, cam: CameraGeometry,
                  steady_from_s: float | None) -> tuple[SwarmMetrics, dict[str, Any]]:
    """Compute the metrics (dashboards/metrics.py), put them into `summary` under "metrics" (with the
    camera they were computed for), write summary.json and the series; return (metrics, summary part)."""
    m = compute_metrics(truth, cam, steady_from_s)
    met = m.summary
    met["camera"] = {"detection_range_m": cam.detection_range_m, "image_px": cam.image_px, "focal_px": cam.focal_px}
    summary["metrics"] = met
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=1))
    np.savez_compressed(run_dir / SERIES, t_s=m.t_s, n_components=m.n_components, largest=m.largest,
                        n_components_orbit=m.n_components_orbit,
                        delta_v_total_mps=m.delta_v_mps.sum(axis=1))
    return m, met


def summary_with_metrics(run_dir: str | Path) -> dict[str, Any]:
    """A run's summary.json with its swarm metrics, computed from run.mcap (and written) if missing."""
    run_dir = Path(run_dir)
    summary = read_summary(run_dir)
    if "metrics" not in summary:
        truth = read_truth(run_dir / "run.mcap", summary.get("run"))
        store_metrics(run_dir, summary, truth, run_camera(run_dir, summary), None)
    return summary
