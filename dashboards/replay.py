"""MCAP recording -> the same Rerun views as the live bridge (`swarmhil replay RUN_DIR/run.mcap`).

The recording is fed, in the order the recorder received it (file order), through the same `SwarmLogger` the live viewer bridge
uses (dashboards/rerun_bridge.py), so a replay shows the same entities with the same values.
The camera rule and trail length come from RUN_DIR/summary.json ("viz" section written by a
live bridge) when present, else from the paper-002 defaults and the recorded mean motion.
"""
from __future__ import annotations

import json
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.keys import Keys, split_topic
from swarmhil.bus.mcap_tools import run_of_recording
from swarmhil.dashboards.rerun_bridge import CameraRule, SwarmLogger, trail_steps_for
from swarmhil.dashboards.run_config import config_from_mcap
from swarmhil.dashboards.viz_node import WebViewer, disable_analytics, free_port, open_recording

UNDECODABLE = pb.UndecodableSample.DESCRIPTOR.full_name


class ReplayError(RuntimeError):
    pass


def _settings(mcap_path: Path, cfg: dict[str, Any] | None) -> tuple[CameraRule, int | None, float | None]:
    """Camera rule, trail steps and step length: from a live bridge's summary.json next to the MCAP
    file, else from the configuration the recording itself carries (dashboards/run_config.py)."""
    try:
        s = json.loads((mcap_path.parent / "summary.json").read_text())
    except (OSError, ValueError):
        if cfg is None:
            return CameraRule(), None, None
        c = cfg["camera"]
        rule = CameraRule(float(c["detection_range_m"]), (c["image_px"] / 2.0) / c["focal_px"])
        viz = cfg.get("viz") or {}
        trail = None
        if viz.get("trail_s"):
            trail = max(1, int(round(viz["trail_s"] / cfg["run"]["step_s"])))
        return rule, trail, float(cfg["run"]["step_s"])
    viz = s.get("viz") or {}
    cam = viz.get("camera") or {}
    rule = CameraRule(float(cam.get("detection_range_m", 500.0)), float(cam.get("tan_half_fov", 0.54)))
    return rule, viz.get("trail_steps"), s.get("step_s")


def _messages(mcap_path: Path):  # type: ignore[no-untyped-def]
    """(topic relative to swarm/<run>/, payload) of every swarmhil sample, in file (reception)
    order: log_time is simulation time, equal for every sample of a step."""
    with open(mcap_path, "rb") as f:
        try:
            reader = make_reader(f)
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                if schema is not None and schema.name == UNDECODABLE:
                    continue
                topic = split_topic(channel.topic)[1]
                if topic.startswith("foxglove/"):
                    continue  # derived from the truth by the recorder
                yield topic, message.data
        except (McapError, EOFError, ValueError) as exc:
            raise ReplayError(f"{mcap_path}: cannot read the recording ({exc}); "
                              f"if its writer was killed, run `swarmhil mcap repair` first") from None


def run_id_of(mcap_path: Path) -> str:
    """The run id: metadata `swarmhil.run`, else the `swarm/<run>/` prefix of an old recording."""
    with open(mcap_path, "rb") as f:
        try:
            run = run_of_recording(make_reader(f))
        except (McapError, EOFError, ValueError) as exc:
            raise ReplayError(f"{mcap_path}: cannot read the recording ({exc}); "
                              f"if its writer was killed, run `swarmhil mcap repair` first") from None
    if run is None:
        raise ReplayError(f"{mcap_path}: no run id (no swarmhil.run metadata, no swarm/<run>/ topics)")
    return run


def replay(mcap_path: str | Path, rrd_out: str | Path | None = None, *, serve: bool = False,
           viz_port: int | None = None, web_port: int | None = None, on_url: Any = None) -> dict[str, Any]:
    """Log a recording to `rrd_out` and/or serve it; returns counts. With serve, on_url(url) is called."""
    mcap_path = Path(mcap_path)
    if rrd_out is None and not serve:
        raise ValueError("give an output .rrd, serve, or both")
    run = run_id_of(mcap_path)
    config = config_from_mcap(mcap_path)
    camera, trail_steps, step_s = _settings(mcap_path, config)
    disable_analytics()
    web = None
    if serve:
        viz_port = viz_port or free_port()
        web_port = web_port or free_port()
    rec = open_recording(run, f"{run}-replay", mode="serve" if serve else "save",
                         rrd=Path(rrd_out) if rrd_out else None, viz_port=viz_port)
    logger = None
    base = Keys(run).base
    try:
        for topic, data in _messages(mcap_path):
            if logger is None:
                logger = _logger_for(rec, run, mcap_path, camera, trail_steps, step_s, config)
            if logger.ingest(f"{base}/{topic}", data):
                logger.flush()
        if logger is None:
            raise ReplayError(f"{mcap_path}: no messages")
        logger.flush(final=True)
        rec.flush()
        stats = logger.stats()
        if serve:
            web = WebViewer(int(web_port), int(viz_port))  # type: ignore[arg-type]
            stats["url"] = web.url
            if on_url:
                on_url(web.url)
            try:
                while web.proc.poll() is None:
                    time.sleep(0.2)
            except KeyboardInterrupt:
                pass
    finally:
        if web is not None:
            web.close()
        rec.disconnect()
    stats["rrd"] = str(rrd_out) if rrd_out else None
    return stats


def _logger_for(rec: Any, run: str, mcap_path: Path, camera: CameraRule, trail_steps: int | None,
                step_s: float | None, config: dict[str, Any] | None) -> SwarmLogger:
    """A logger whose trail defaults to one orbit of the recorded reference orbit."""
    n_radps, dt = None, step_s
    for topic, data in _messages(mcap_path):
        if topic == "truth":
            msg = pb.Truth.FromString(data)
            n_radps = msg.mean_motion_radps or None
            if dt is None and msg.header.step > 0:
                dt = msg.header.t / msg.header.step
            if dt is not None:
                break
    dt = dt or 10.0
    steps = trail_steps or (trail_steps_for(dt, n_radps) if n_radps else 570)
    return SwarmLogger(rec, run, camera=camera, trail_steps=int(steps), step_s=dt, config=config)


def read_rrd(path: str | Path, timeline: str = "step") -> dict[str, dict[str, dict[int, Any]]]:
    """{entity path: {component: {time on `timeline`: value}}} of a .rrd's recording.

    Of several rows at one time the latest (highest row id) wins, as in the viewer. Static data
    appears under time -1. Values are plain Python lists (pyarrow `to_pylist`).
    """
    from rerun.chunk import RrdReader

    rows: dict[tuple[str, str, int], tuple[bytes, Any]] = {}
    for chunk in RrdReader(str(path)).stream():
        rb = chunk.to_record_batch()
        names = rb.schema.names
        if chunk.is_static:
            times = [-1] * rb.num_rows
        elif timeline in names:
            times = rb.column(names.index(timeline)).to_pylist()
        else:
            continue
        row_ids = rb.column(names.index("rerun.controls.RowId")).to_pylist()
        for ci, name in enumerate(names):
            if name.startswith("rerun.controls") or name in ("step", "sim_time", "log_time", "log_tick"):
                continue
            for rid, t, v in zip(row_ids, times, rb.column(ci).to_pylist()):
                key = (chunk.entity_path, name, t)
                if v is not None and (key not in rows or rows[key][0] < rid):
                    rows[key] = (rid, v)
    out: dict[str, dict[str, dict[int, Any]]] = defaultdict(lambda: defaultdict(dict))
    for (entity, name, t), (_rid, v) in rows.items():
        out[entity][name][t] = v
    return {e: dict(c) for e, c in out.items()}
