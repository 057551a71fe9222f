"""The recorder: every sample on swarm/<run>/** into one MCAP file (DESIGN.md "MCAP (contract)").

topic = the key without its `swarm/<run>/` prefix (`truth`, `sc/sc01/act`), log_time = the
scenario epoch (`[run].epoch_utc`) + the sample's simulation time (header.t; a sample without one
keeps the last), publish_time = the recorder's reception wall time (ns since 1970), schema = the
protobuf FileDescriptorSet of the key's message type (registered once per type), message
encoding `protobuf`, zstd chunks. With every truth it also writes Foxglove's own
`foxglove.FrameTransforms` (`foxglove/tf`) and `foxglove.SceneUpdate` (`foxglove/scene`), and
with every event a `foxglove.Log` (`foxglove/log`): bus/foxglove_scene.py. A payload that does not parse as its key's type is kept too,
wrapped in `swarmhil.v1.UndecodableSample` on the same topic, so readers never trip on it; an
ActuatorCommand the plant does not act on (another run's or another source's, bus/codec.py
`command_rejection`) is kept as a `swarmhil.v1.RejectedSample`, so it never reads as an accepted
command. Both carry the step and time the run was at when they arrived.
A killed recorder loses at most its open chunk, which is written out at the first clock tick after
`FLUSH_PERIOD_S` (1 s) of wall time: so about a second; `swarmhil mcap repair` salvages the rest,
and the launcher restarts a killed recorder into a new segment `run.NNN.mcap` (metadata
`swarmhil.segment`) that `swarmhil mcap merge` joins to the others (bus/mcap_tools.py).

Flush handshake (the launcher's shutdown, issue 10): a payload on `flush_key(run)` (outside the
recorded swarm/<run>/** namespace) is answered on `ack_key(run)` with JSON {"nonce", "messages",
"by_topic", "run_end"}: what the recorder has written so far, and whether the plant's `run_end`
event is among it. The request goes through the same dispatcher queue as the recorded samples,
so the answer covers every sample the recorder received before the request.
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf.message import DecodeError, Message
from mcap_protobuf.schema import build_file_descriptor_set

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.base import Bus
from swarmhil.bus.bulk_wire import Prepared
from swarmhil.bus.codec import command_rejection, message_type_of_topic, sim_time_ns
from swarmhil.bus.foxglove_scene import SCENE_TOPIC, TF_TOPIC, FoxgloveScene
from swarmhil.bus.mcap_writer import BulkRecords, RecorderWriter
from swarmhil.bus.keys import Keys

log = logging.getLogger("swarmhil.recorder")

CHUNK_SIZE = 256 * 1024
FLUSH_PERIOD_S = 1.0  # the open chunk is written out at the first clock tick after this much wall time
DEFAULT_EPOCH_UTC = "2000-01-01T12:00:00Z"  # deploy/scenario.py [run].epoch_utc


def epoch_ns(epoch_utc: str | None) -> int:
    """Nanoseconds since 1970 of an ISO 8601 UTC epoch (the default when None)."""
    from datetime import datetime, timezone

    dt = datetime.fromisoformat(epoch_utc or DEFAULT_EPOCH_UTC)
    dt = dt.replace(tzinfo=timezone.utc) if dt.tzinfo is None else dt
    return int(dt.timestamp()) * 1_000_000_000 + dt.microsecond * 1000


def message_type_for_key(keys: Keys, key: str) -> type[Message] | None:
    try:
        keys.parse(key)
    except ValueError:
        return None
    return message_type_of_topic(key)


def parse_sample(cls: type[Message] | None, payload: bytes) -> tuple[Message | None, int | None, str]:
    """(message, its simulation time in ns or None, why it does not parse: "" when it does).

    The time is header.t where the message has a header with a finite, sane t (NaN/inf packets
    keep the last time). Shared by the recorder and the live Foxglove server."""
    if cls is None:
        return None, None, "key outside the swarmhil contract"
    try:
        msg = cls.FromString(payload)
    except (DecodeError, RuntimeWarning, ValueError) as exc:
        return None, None, f"does not parse as {cls.DESCRIPTOR.full_name}: {exc}"
    hdr = getattr(msg, "header", None)
    if hdr is not None and hasattr(hdr, "t") and msg.HasField("header"):
        return msg, sim_time_ns(hdr.t), ""
    return msg, None, ""


class McapRecorder:
    """Writes raw, already-serialised samples; safe to call from one thread (the bus dispatcher)."""

    def __init__(self, path: str | Path, run: str, *, chunk_size: int = CHUNK_SIZE, epoch_utc: str | None = None,
                 config: dict[str, Any] | None = None, foxglove: bool = True,
                 flush_period_s: float | None = FLUSH_PERIOD_S, background: bool = False) -> None:
        self.path = Path(path)
        self.keys = Keys(run)
        self.run = run
        self.epoch_ns = epoch_ns(epoch_utc)
        self._scene = FoxgloveScene(config) if foxglove else None
        # per key: (class, topic, the scene derives from the class): a run has few distinct keys, each looked at once
        self._key_info: dict[str, tuple[type[Message] | None, str, bool]] = {}
        self._f: BinaryIO = open(self.path, "wb")
        # zstd chunks (bus/mcap_writer.py), compressed on a worker thread when `background`
        self._w = RecorderWriter(self._f, chunk_size=chunk_size, background=background)
        self._w.start(profile="", library="swarmhil")
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._topic_channel: dict[str, tuple[type[Message], int]] = {}  # topic -> (type, channel) of its last sample
        self.count = 0
        self.undecodable = 0
        self.rejected = 0          # commands written as RejectedSample (bus/codec.py command_rejection)
        self._last_step = 0        # the step of the last clock tick: the step an undecodable or rejected sample arrived in
        self._by_topic: dict[str, list[int]] = {}  # topic -> [messages, bytes]
        self._cid_topic: dict[int, str] = {}  # channel -> topic, of the channels `write_many` writes
        self._many: list[tuple[Any, Any]] = []  # write_many's and write_records' (channels, message sizes) not yet in _by_topic
        self._last_t_ns = 0
        self._closed = False
        self._flush_period_s = flush_period_s
        self._last_flush = time.monotonic()
        # the bodies (ids, kinds, alive, positions) of the next truth sample, from its publisher in this
        # process (a batch run: deploy/batch_packets.py): the Foxglove scene from them, the truth not decoded
        self.next_truth: tuple[list[str], list[str], list[bool], np.ndarray] | None = None

    def _schema_id(self, cls: type[Message]) -> int:
        name = cls.DESCRIPTOR.full_name
        sid = self._schemas.get(name)
        if sid is None:
            sid = self._w.register_schema(name=name, encoding="protobuf",
                                          data=build_file_descriptor_set(cls).SerializeToString())
            self._schemas[name] = sid
        return sid

    def _channel_id(self, topic: str, cls: type[Message]) -> int:
        ck = (topic, cls.DESCRIPTOR.full_name)
        cid = self._channels.get(ck)
        if cid is None:
            cid = self._w.register_channel(topic=topic, message_encoding="protobuf", schema_id=self._schema_id(cls))
            self._channels[ck] = cid
        return cid

    def _add(self, topic: str, cls: type[Message], payload: bytes, t_ns: int, wall_ns: int) -> None:
        cid = self._topic_channel.get(topic)  # (the channel of a topic's usual type, looked up once)
        if cid is None or cid[0] is not cls:
            cid = self._topic_channel[topic] = (cls, self._channel_id(topic, cls))
        self._w.add_message(cid[1], self.epoch_ns + max(t_ns, 0), payload, wall_ns, self.count)
        self.count += 1
        tally = self._by_topic.get(topic)
        if tally is None:
            tally = self._by_topic[topic] = [0, 0]
        tally[0] += 1
        tally[1] += len(payload)

    def channels(self, keys: list[str], classes: list[type[Message]]) -> list[int]:
        """The channel of each key (its topic) with its message class, registered on first use: what
        `write_many` takes."""
        out = []
        for key, cls in zip(keys, classes):
            topic = self.keys.topic(key)
            cid = self._channel_id(topic, cls)
            self._cid_topic[cid] = topic
            out.append(cid)
        return out

    def write_many(self, channel_ids: list[int], blob: bytes, starts: np.ndarray, sizes: np.ndarray,
                   t_ns: "int | np.ndarray | None", wall_time_ns: int | None = None) -> None:
        """Already-serialised messages of simulation time t_ns (one for all, or each one's (n,) array
        of usable times), in this order: message i is blob[starts[i]:starts[i] + sizes[i]] on
        channel_ids[i] (`channels`). The records `write` makes for them one by one (publisher-stamped
        samples of a class the Foxglove scene does not derive from, or whose derivation the caller
        does: `scene`), as one buffer; t_ns None keeps the last time."""
        if self._closed or not channel_ids:
            return
        wall_ns = time.time_ns() if wall_time_ns is None else wall_time_ns
        log_time: int | np.ndarray
        if isinstance(t_ns, np.ndarray):
            self._last_t_ns = max(self._last_t_ns, int(t_ns.max()))
            log_time = self.epoch_ns + np.maximum(t_ns, 0)
        else:
            if t_ns is None:  # (a time that is not usable: the last, as `write`)
                t_ns = self._last_t_ns
            elif t_ns > self._last_t_ns:
                self._last_t_ns = t_ns
            log_time = self.epoch_ns + max(t_ns, 0)
        self._w.add_messages(channel_ids, log_time, blob, starts, sizes, wall_ns, self.count)
        self.count += len(channel_ids)
        self._many.append((channel_ids, sizes))

    def write_records(self, records: BulkRecords, parts: list[Prepared], channel_ids: np.ndarray, t_ns: int | None,
                      wall_time_ns: int | None = None) -> None:
        """`write_many` of the messages of bus/bulk_wire.py encoders (`parts`, interleaved message by
        message, on `channel_ids`), their records made by `records` in one gather."""
        if self._closed or not len(channel_ids):
            return
        wall_ns = time.time_ns() if wall_time_ns is None else wall_time_ns
        if t_ns is None:
            t_ns = self._last_t_ns
        elif t_ns > self._last_t_ns:
            self._last_t_ns = t_ns
        log_time = self.epoch_ns + max(t_ns, 0)
        data, starts, sizes = records.take(parts, channel_ids, self.count, log_time, wall_ns)
        self._w.add_records(channel_ids, log_time, data, starts)
        self.count += len(channel_ids)
        self._many.append((channel_ids, sizes))

    @property
    def scene(self) -> FoxgloveScene | None:
        """The Foxglove scene the recorder derives (None: not recorded)."""
        return self._scene

    def _tally_many(self) -> None:
        """Fold the counts of `write_many` into the per-topic tallies."""
        for cids, sizes in self._many:
            for cid, b in zip(np.asarray(cids).tolist(), np.asarray(sizes).tolist()):
                tally = self._by_topic.get(self._cid_topic[cid])
                if tally is None:
                    tally = self._by_topic[self._cid_topic[cid]] = [0, 0]
                tally[0] += 1
                tally[1] += b
        self._many.clear()

    @property
    def by_topic(self) -> dict[str, int]:
        """Messages written per topic."""
        self._tally_many()
        return {topic: n for topic, (n, _b) in self._by_topic.items()}

    @property
    def bytes_by_topic(self) -> dict[str, int]:
        """Payload bytes written per topic."""
        self._tally_many()
        return {topic: b for topic, (_n, b) in self._by_topic.items()}

    def _key(self, key: str) -> tuple[type[Message] | None, str, bool]:
        """The per-key entry of `write`: class, topic, whether the Foxglove scene derives from it."""
        cls = message_type_for_key(self.keys, key)
        info = self._key_info[key] = (cls, self.keys.topic(key), self._scene is not None and cls in self._scene.DERIVES_FROM)
        return info

    def write(self, key: str, payload: bytes, wall_time_ns: int | None = None, t_ns: int | None = None) -> None:
        """One sample: log_time = epoch + its simulation time, publish_time = reception wall time.

        `t_ns`: the simulation time the publisher stamped the sample with (bus/memory.py, a
        publisher in this process that serialised a message of the key's type): the payload is
        then not decoded again unless the Foxglove scene derives from its class (stimuli and
        commands, the bulk of a paper 000 run's bytes, are not). A sample that does not parse, or
        of a key outside the contract, is written as an UndecodableSample and counted."""
        if self._closed:
            return
        wall_ns = time.time_ns() if wall_time_ns is None else wall_time_ns
        info = self._key_info.get(key)
        cls, topic, derives = self._key(key) if info is None else info
        t: int | None
        msg: Message | None
        bodies, self.next_truth = self.next_truth, None
        if t_ns is not None and cls is not None and (not derives or (bodies is not None and cls is pb.Truth)):
            msg, t, reason = None, t_ns, ""
        else:
            msg, t, reason = parse_sample(cls, payload)
            bodies = None
        at_ns = self._last_t_ns if t is None else t
        rejected = command_rejection(msg, key.rsplit("/", 2)[-2], self.run) \
            if cls is pb.ActuatorCommand and msg is not None else None
        if reason:
            self.undecodable += 1
            wrapped = pb.UndecodableSample(key=key, payload=payload, reason=reason, header=self._arrival())
            cls, payload, msg = pb.UndecodableSample, wrapped.SerializeToString(), None
        elif rejected:  # a command the plant does not act on: never recorded as one it did
            self.rejected += 1
            at_ns = self._last_t_ns
            hdr: Any = getattr(msg, "header")
            wrapped = pb.RejectedSample(key=key, payload=payload, reason=rejected, header=self._arrival(),
                                        claimed_source=hdr.source, claimed_run=hdr.run)
            cls, payload, msg = pb.RejectedSample, wrapped.SerializeToString(), None
        else:
            if cls is pb.Tick:
                self._last_step = int((msg or pb.Tick.FromString(payload)).header.step)  # type: ignore[attr-defined]
            if at_ns > self._last_t_ns:
                self._last_t_ns = at_ns
        assert cls is not None  # a sample of an unknown key is parse_sample's reason, wrapped above
        self._add(topic, cls, payload, at_ns, wall_ns)
        if cls is pb.Tick and self._flush_period_s is not None and time.monotonic() - self._last_flush >= self._flush_period_s:
            self._w.flush()  # what a SIGKILL would lose: at most the chunk since the last flush
            self._last_flush = time.monotonic()
        if self._scene is not None and msg is not None:
            for d_topic, d_cls, d_payload in self._scene.derive(cls, msg, topic, self.epoch_ns + max(at_ns, 0)):
                self._add(d_topic, d_cls, d_payload, at_ns, wall_ns)
        elif self._scene is not None and bodies is not None:  # the truth's bodies as arrays (`next_truth`)
            tf, scene = self._scene.from_bodies(*bodies, self.epoch_ns + max(at_ns, 0))
            self._add(TF_TOPIC, FrameTransforms, tf, at_ns, wall_ns)
            self._add(SCENE_TOPIC, SceneUpdate, scene, at_ns, wall_ns)

    def _arrival(self) -> Any:
        """The header of a sample the recorder wraps: the run, source "recorder", and the step and
        simulation time the run was at when it arrived (the last clock tick's)."""
        return pb.Header(run=self.run, source="recorder", step=self._last_step, t=self._last_t_ns / 1e9)

    def describe_run(self, config: dict[str, Any], document: dict[str, Any] | None = None) -> None:
        """MCAP metadata "swarmhil.run" (run id, software version) and "swarmhil.config" (the fully
        resolved configuration as JSON, key "json"), and the validated scenario document as the
        attachment "scenario.json" (DESIGN, MCAP contract): a recording needs nothing else."""
        import json

        self._w.add_metadata("swarmhil.run", {"run": self.run, "software_version": str(config.get("software_version")),
                                              "scenario": str(config.get("run", {}).get("name")),
                                              "scenario_file": str(config.get("scenario_file")),
                                              "epoch_utc": str(config.get("run", {}).get("epoch_utc") or DEFAULT_EPOCH_UTC),
                                              "topics": "relative"})
        self._w.add_metadata("swarmhil.config", {"json": json.dumps(config, default=float)})
        if document is not None:
            self._w.add_attachment(create_time=time.time_ns(), log_time=0, name="scenario.json",
                                   media_type="application/json", data=json.dumps(document, indent=1).encode())

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._w.add_metadata(name, data)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._w.finish()
        self._f.close()


def flush_key(run: str) -> str:
    return Keys(run).recorder_flush


def ack_key(run: str) -> str:
    return Keys(run).recorder_ack


RECORD_CHOICES = ("all", "truth")


class RecorderNode:
    """Subscribes to everything of the run and hands each sample to the MCAP writer.

    record="truth" (issue 16: a campaign row needs only the truth): only the `truth`, `event` and
    `faults` topics, without the Foxglove scene, transforms and log written alongside. `background`: the
    chunks are compressed on a worker thread (an in-process run: bus/mcap_writer.py)."""

    def __init__(self, bus: Bus, run: str, path: str | Path, config: dict[str, Any] | None = None,
                 document: dict[str, Any] | None = None, segment: int = 0, record: str = "all",
                 background: bool = False) -> None:
        if record not in RECORD_CHOICES:
            raise ValueError(f"unknown record {record!r}; known: {', '.join(RECORD_CHOICES)}")
        self.bus = bus
        self.run = run
        self.keys = Keys(run)
        epoch = ((config or {}).get("run") or {}).get("epoch_utc")
        self.rec = McapRecorder(path, run, epoch_utc=epoch, config=config, foxglove=record == "all",
                                background=background)
        if config is not None:
            self.rec.describe_run(config, document)
        if segment:  # a restarted recorder: this file continues the run after a gap (bus/mcap_tools.merge)
            self.rec.add_metadata("swarmhil.segment", {"index": str(segment), "file": Path(path).name,
                                                       "started_wall_ns": str(time.time_ns())})
        self.run_end = False
        # on a bus that carries the publishers' simulation time (bus/memory.py), take it from there
        stamped = {"stamped": True} if getattr(bus, "stamps", False) else {}
        self._k_event = self.keys.event
        keys = (self.keys.all,) if record == "all" else (self.keys.truth, self.keys.event, self.keys.faults)
        self._subs = [bus.subscribe(k, self._on_sample, **stamped) for k in keys]
        self._flush_sub = bus.subscribe(flush_key(run), self._on_flush)
        self._token = bus.declare_liveliness(self.keys.alive("recorder"))

    def _on_sample(self, key: str, payload: bytes, t_ns: int | None = None) -> None:
        self.rec.write(key, payload, t_ns=t_ns)
        if key == self._k_event and not self.run_end:
            try:
                ev = pb.Event.FromString(payload)
            except (DecodeError, RuntimeWarning, ValueError):
                return
            self.run_end = ev.kind == "run_end" and ev.header.source == "plant"

    def _on_flush(self, _key: str, payload: bytes) -> None:
        ack = {"nonce": payload.decode(errors="replace"), "messages": self.rec.count,
               "by_topic": dict(self.rec.by_topic), "run_end": self.run_end}
        self.bus.publish(ack_key(self.run), json.dumps(ack).encode())

    def close(self) -> dict[str, int]:
        for sub in (*self._subs, self._flush_sub):
            try:
                sub.undeclare()
            except Exception:
                pass
        flush = getattr(self.bus, "flush", None)
        if flush:
            flush()
        self.rec.close()
        return {"messages": self.rec.count, "undecodable": self.rec.undecodable, "rejected": self.rec.rejected}
