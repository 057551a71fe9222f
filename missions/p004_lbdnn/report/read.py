"""Paper 004's report, reading (issue 25: a report split by job, like dashboards/navreport/): from
the recording, the defunct craft's truth (a body, not a spacecraft: the raw Truth messages of the
MCAP) and, from the resolved configuration, which craft is the defunct one, which are servicers and
the mission's graph / C_i / b_i (missions/p004_lbdnn/contract.py mission_from_params).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.truth_io import TRUTH_SCHEMA, _truth_topic
from swarmhil.missions.p004_lbdnn.contract import CONTROLLER, MissionConfig, mission_from_params


def defunct_id(config: dict[str, Any]) -> str:
    """The defunct craft: the sensing kind's defunct_id, else the configuration's first body."""
    sid = ((config.get("sensing") or {}).get("params") or {}).get("defunct_id")
    if sid:
        return str(sid)
    bodies = config.get("body") or []
    if not bodies:
        raise ValueError("the recording's configuration has no body (defunct craft)")
    return str(bodies[0]["id"])


def read_body(mcap_path: Path, body_id: str, run: str | None = None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{step: (position, velocity)} of one body (any kind) from the recording's Truth messages
    (scenario frame), with the standard reader (mcap + mcap-protobuf-support)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    rows: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topic, _run = _truth_topic(reader, run)
        for schema, _ch, _msg, truth in reader.iter_decoded_messages(topics=[topic]):
            if schema is None or schema.name != TRUTH_SCHEMA:
                continue
            step = int(truth.header.step)
            if step in rows:
                continue
            for b in truth.bodies:
                if b.id == body_id:
                    rows[step] = (np.array([b.position_m.x, b.position_m.y, b.position_m.z]),
                                  np.array([b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z]))
                    break
    return rows


def servicers(config: dict[str, Any], ids: list[str]) -> list[str]:
    """The spacecraft flown by p004-lbdnn (all of them when it is the swarm's controller)."""
    swarm = str((config.get("controller") or {}).get("name")) == CONTROLLER
    own = {str(s["id"]): s.get("controller") for s in config.get("spacecraft") or []}
    return [i for i in ids if (own.get(i) == CONTROLLER) or (swarm and not own.get(i))]


def mission_of(config: dict[str, Any]) -> MissionConfig:
    """The mission (graph, C_i, b_i) of the controller's params in the configuration."""
    return mission_from_params(dict((config.get("controller") or {}).get("params") or {}))
