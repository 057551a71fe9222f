"""Reading a run's link traffic from its recording (`isl/tx`, `isl/rx`, `link/stats`, the channel's
`link_config` event, truth) and its summary.json: `LinkTraffic`."""
from __future__ import annotations

import json
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.bus.keys import split_topic
from swarmhil.bus.mcap_tools import run_of_recording
from swarmhil.link.model import (
    COUNTER_FIELDS,
    DROP_CAUSES,
    check_tx,
    line_of_sight_clear,
    reason_class,
)


@dataclass
class LinkTraffic:
    """Everything of one run the bandwidth report needs, decoded from its recording."""

    run: str
    ids: list[str]
    config: dict[str, Any]
    step_s: float
    t_end_s: float = 0.0
    # accepted transmissions: (t, src, dst, type, payload_bytes)
    tx: list[tuple[float, str, str, str, int]] = field(default_factory=list)
    # deliveries: (t_rx, sent_t, src, receiver, type, payload_bytes)
    rx: list[tuple[float, float, str, str, str, int]] = field(default_factory=list)
    rejected_tx: Counter = field(default_factory=Counter)       # reason class -> count (from the MCAP)
    rejected_events: int = 0
    stats_rows: dict[tuple[str, str, str], list[int]] = field(default_factory=dict)  # last LinkStats
    stats_rejected: int | None = None
    stats_tx_messages: int | None = None
    stats_rx_messages: int | None = None
    stats_t_s: float | None = None
    stats_series: list[tuple[float, dict[str, int]]] = field(default_factory=list)
    beyond_range: int = 0          # deliveries to a receiver out of range at the time of sending
    occulted_delivered: int = 0    # deliveries through the Earth
    unchecked_geometry: int = 0    # deliveries whose sending-time truth is not in the recording
    summary_channel: dict[str, Any] | None = None

    @property
    def has_link(self) -> bool:
        """False for a run without the link channel (no [link] in its scenario): no link configuration,
        no transmission, delivery or counter in the recording or the summary."""
        return bool(set(self.config) - {"ids"} or self.tx or self.rx or self.rejected_tx or self.stats_series
                    or self.summary_channel)

    @property
    def overhead_bytes(self) -> int:
        return int(self.config.get("overhead_bytes", 0))


def _topic_kind(topic: str) -> tuple[str, str | None]:
    """Kind and id of an MCAP topic: `isl/tx/sc01` (or the old `swarm/<run>/isl/tx/sc01`)."""
    parts = split_topic(topic)[1].split("/")
    if len(parts) == 3 and parts[0] == "isl" and parts[1] in ("tx", "rx"):
        return f"isl_{parts[1]}", parts[2]
    if parts == ["link", "stats"]:
        return "link_stats", None
    if len(parts) == 1 and parts[0] in ("truth", "event"):
        return parts[0], None
    return "other", None


def _finite(*xs: float) -> bool:
    return all(math.isfinite(x) for x in xs)


def read_link_traffic(run_dir: str | Path) -> LinkTraffic:
    """Decode the link traffic of run_dir/run.mcap (and read run_dir/summary.json when present)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    run_dir = Path(run_dir)
    spath = run_dir / "summary.json"
    summary = json.loads(spath.read_text()) if spath.is_file() else {}
    run = summary.get("run")
    truth: dict[int, tuple[dict[str, np.ndarray], float]] = {}
    tx_raw: list[tuple[str, Any, str]] = []   # (key id, decoded msg, schema name)
    rx_raw: list[tuple[str, Any]] = []
    config: dict[str, Any] | None = None
    stats_series: list[tuple[float, Any]] = []
    rejected_events = 0
    t_end = 0.0
    with open(run_dir / "run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        s = reader.get_summary()
        topics = sorted({ch.topic for ch in s.channels.values()}) if s is not None else []
        if run is None:
            run = run_of_recording(reader)
            if run is None:
                raise ValueError(f"{run_dir}: cannot tell the run id (no swarmhil.run metadata, no single swarm/<run>/ prefix)")

        wanted = [t for t in topics if split_topic(t)[0] in (None, run) and _topic_kind(t)[0] in
                  ("isl_tx", "isl_rx", "link_stats", "truth", "event")]
        for schema, channel, message, msg in reader.iter_decoded_messages(topics=wanted):
            kind, key_id = _topic_kind(channel.topic)
            if kind == "truth":
                pos = {b.id: np.array([b.position_m.x, b.position_m.y, b.position_m.z]) for b in msg.bodies}
                truth[int(round(msg.header.t * 1000))] = (pos, msg.semi_major_axis_m)
                t_end = max(t_end, msg.header.t)
            elif kind == "isl_tx":
                tx_raw.append((key_id, msg, schema.name))
            elif kind == "isl_rx":
                rx_raw.append((key_id, msg))
            elif kind == "link_stats":
                stats_series.append((msg.header.t, msg))
            elif kind == "event" and msg.header.source == "channel":
                if msg.kind == "link_config":
                    config = json.loads(msg.detail)
                elif msg.kind == "rejected_packet":
                    rejected_events += 1
    if config is None:
        config = dict((summary.get("channel") or {}).get("config") or {})
        config.setdefault("ids", [])
    ids = list(config.get("ids") or sorted({i for p, _a in truth.values() for i in p}))
    step_s = float(config.get("step_s", summary.get("step_s", 1.0)))
    lt = LinkTraffic(run=run, ids=ids, config=config, step_s=step_s, t_end_s=t_end,
                     rejected_events=rejected_events, summary_channel=summary.get("channel"))
    known = set(ids)
    max_payload = int(config.get("max_payload_bytes", 1 << 62))
    for key_id, m, schema_name in tx_raw:
        if schema_name != "swarmhil.v1.IslPacket":
            lt.rejected_tx["malformed"] += 1
            continue
        if m.header.run != run or not _finite(m.header.t, m.sent_t):
            lt.rejected_tx["malformed"] += 1
            continue
        reason = check_tx(key_id, m.src, m.dst, len(m.payload), known, max_payload)
        if reason:
            lt.rejected_tx[reason_class(reason)] += 1
            continue
        lt.tx.append((m.header.t, m.src, m.dst, m.type, len(m.payload)))
    range_m = float(config.get("range_m", math.inf))
    occ = bool(config.get("occultation", False))
    r_block = float(config.get("earth_radius_m", 6378137.0)) + float(config.get("grazing_altitude_m", 0.0))
    for key_id, m in rx_raw:
        lt.rx.append((m.header.t, m.sent_t, m.src, key_id, m.type, len(m.payload)))
        at = truth.get(int(round(m.sent_t * 1000)))
        if at is None or m.src not in at[0] or key_id not in at[0]:
            lt.unchecked_geometry += 1
            continue
        p1, p2 = at[0][m.src], at[0][key_id]
        if float(np.linalg.norm(p2 - p1)) > range_m:
            lt.beyond_range += 1
        if occ and not line_of_sight_clear(p1, p2, at[1], r_block):
            lt.occulted_delivered += 1
    for t, st in stats_series:
        lt.stats_series.append((t, {"tx_messages": st.tx_messages, "rx_messages": st.rx_messages,
                                    **{f"dropped_{c}": sum(getattr(c_, f"dropped_{c}") for c_ in st.links)
                                       for c in DROP_CAUSES}}))
    if stats_series:
        t, last = stats_series[-1]
        lt.stats_t_s = t
        lt.stats_rejected = int(last.rejected_packets)
        lt.stats_tx_messages = int(last.tx_messages)
        lt.stats_rx_messages = int(last.rx_messages)
        lt.stats_rows = {(c.src, c.dst, c.type): [int(getattr(c, n)) for n in COUNTER_FIELDS] for c in last.links}
    return lt


def traffic_of(run: str | Path | LinkTraffic) -> LinkTraffic:
    return run if isinstance(run, LinkTraffic) else read_link_traffic(run)

