"""Paper 000's report, reading (issue 25: a report split by job, like dashboards/navreport/): from
the recording, what the section needs besides ctx.truth: the target's pose and attitude and the
spacecraft attitudes and rates from the raw Truth messages (standard mcap reader), each agent's
mode and estimates from its `sc/<id>/tm` telemetry, the packets sent from the `isl/tx/<id>`
topics; from the resolved configuration, the target's semi-axes and the controller's params
(controller.params merged with each spacecraft's params, as deploy/scenario.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.bus.codec import measurements_to_dict
from swarmhil.bus.keys import split_topic
from swarmhil.dashboards.truth_io import TRUTH_SCHEMA, _truth_topic
from swarmhil.missions.p000_capture.contract import CaptureParams


@dataclass
class CaptureRecording:
    """What the section reads from the MCAP besides ctx.truth (rows = Truth steps, sorted)."""

    steps: np.ndarray            # (K,)
    target_id: str
    target_pos: np.ndarray       # (K, 3) CW frame
    target_q: np.ndarray         # (K, 4) scalar-first, body -> CW frame (the target's attitude in truth)
    sc_q: np.ndarray             # (K, N, 4) body -> inertial frame aligned with CW at t = 0 (NaN if not flown)
    modes: dict[str, dict[int, str]]      # id -> step -> telemetry mode
    tx: list[tuple[str, str, int, int]]   # (src, type, payload bytes, step) of every isl/tx packet
    sc_w: np.ndarray | None = None        # (K, N, 3) body rates [rad/s] (NaN if not flown)
    est_axes: np.ndarray | None = None    # (K, N, 3) the agent's sorted semi-axes estimate (telemetry; NaN: none)
    est_centre: np.ndarray | None = None  # (K, N, 3) its centroid estimate at that step (CW frame)
    est_surface: np.ndarray | None = None  # (K, N) its signed distance to its ESTIMATED surface


def read_capture(mcap: Path, ids: list[str], run: str | None = None) -> CaptureRecording:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    tgt: dict[int, tuple] = {}
    att: dict[int, np.ndarray] = {}
    modes: dict[str, dict[int, str]] = {}
    tx: list[tuple[str, str, int, int]] = []
    rates: dict[int, np.ndarray] = {}
    est: dict[tuple[int, int], dict[str, np.ndarray]] = {}  # (step, column) -> telemetry items
    tid = ""
    col = {s: j for j, s in enumerate(ids)}
    with open(mcap, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        truth_topic, _run = _truth_topic(reader, run)
        summ = reader.get_summary()
        topics = [truth_topic] + sorted({
            ch.topic for ch in (summ.channels.values() if summ is not None else [])
            if (split_topic(ch.topic)[1].startswith("sc/") and split_topic(ch.topic)[1].endswith("/tm"))
            or split_topic(ch.topic)[1].startswith("isl/tx/")})
        for schema, ch, _msg, m in reader.iter_decoded_messages(topics=topics):  # not the big sensing ones
            rel = split_topic(ch.topic)[1]
            if ch.topic == truth_topic:
                k = int(m.header.step)
                if schema is None or schema.name != TRUTH_SCHEMA or k in tgt:
                    continue
                q = np.full((len(ids), 4), np.nan)
                w = np.full((len(ids), 3), np.nan)
                for b in m.bodies:
                    if b.kind == "target" and k not in tgt:
                        tid = b.id
                        tgt[k] = ((b.position_m.x, b.position_m.y, b.position_m.z),
                                  (b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z))
                    elif b.kind == "spacecraft" and b.id in col and b.HasField("attitude"):
                        q[col[b.id]] = (b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z)
                        if b.HasField("angular_velocity_radps"):
                            av = b.angular_velocity_radps
                            w[col[b.id]] = (av.x, av.y, av.z)
                att[k], rates[k] = q, w
            elif rel.startswith("sc/") and rel.endswith("/tm"):
                sid = m.header.source or rel.split("/")[1]
                modes.setdefault(sid, {})[int(m.header.step)] = m.mode
                if len(m.items) and sid in col:
                    est[(int(m.header.step), col[sid])] = measurements_to_dict(m)
            elif rel.startswith("isl/tx/"):
                tx.append((m.src, m.type, len(m.payload), int(m.header.step)))
    if not tgt:
        raise ValueError(f"{mcap}: no body of kind 'target' in the truth")
    steps = np.array(sorted(tgt))
    row = {int(k): r for r, k in enumerate(steps)}
    e_axes = np.full((len(steps), len(ids), 3), np.nan)
    e_centre, e_surf = e_axes.copy(), np.full((len(steps), len(ids)), np.nan)
    for (k, j), items in est.items():
        if k in row:
            e_axes[row[k], j] = items.get("p000_axes_est_m", np.nan)
            e_centre[row[k], j] = items.get("p000_centre_est_m", np.nan)
            e_surf[row[k], j] = np.ravel(items.get("p000_surface_est_m", [np.nan]))[0]
    return CaptureRecording(
        steps=steps, target_id=tid, target_pos=np.array([tgt[k][0] for k in steps], dtype=float),
        target_q=np.array([tgt[k][1] for k in steps], dtype=float),
        sc_q=np.array([att[k] for k in steps], dtype=float), modes=modes, tx=tx,
        sc_w=np.array([rates[k] for k in steps], dtype=float), est_axes=e_axes, est_centre=e_centre,
        est_surface=e_surf)



def target_axes(cfg: dict[str, Any] | None) -> np.ndarray:
    """The semi-axes of the configuration's body of kind "target" (an ellipsoid)."""
    for b in (cfg or {}).get("body") or []:
        if b.get("kind") == "target" and (b.get("shape") or {}).get("kind") == "ellipsoid":
            return np.asarray(b["shape"]["semi_axes_m"], dtype=float)
    raise ValueError("the configuration has no ellipsoidal body of kind 'target'")



def capture_params(cfg: dict[str, Any] | None, sid: str):

    cfg = cfg or {}
    scs = {str(s["id"]): s for s in cfg.get("spacecraft") or []}
    p = {**((cfg.get("controller") or {}).get("params") or {}), **((scs.get(sid) or {}).get("params") or {})}
    return CaptureParams.from_dict(p)

