"""Live Foxglove (`swarmhil run ... --viz foxglove`): the run over a Foxglove WebSocket server.

The viewer bridge (dashboards/viz_node.py, mode "foxglove") hands every sample it receives to
`FoxgloveLive.ingest`, which sends it on as the recorder writes it (bus/recorder.py): the same
topics (the key without `swarm/<run>/`: `truth`, `sc/<id>/tm`, `link/stats`, `event`, `isl/rx/<id>`,
`sc/<id>/tm/image`), the same protobuf schemas, log time = the scenario epoch + the simulation
time, and the same derived `foxglove/tf` (FrameTransforms), `foxglove/scene` (SceneUpdate) and
`foxglove/log` (Log) made by the one builder `bus/foxglove_scene.FoxgloveScene.derive`. So the
shipped layout (dashboards/foxglove/swarmhil-layout.json) shows a live run as it shows its
recording.

The server is `foxglove-sdk`'s (protocol foxglove.websocket.v1), in its own `foxglove.Context`,
bound to 127.0.0.1 only, on `--viz-port` (default 8765, Foxglove's own default). Channels are made
when their topic first appears; a client sees them advertised and subscribes. The server does not
keep history: a client that joins late sees the run from then on (the recording has all of it).
"""
from __future__ import annotations

import logging
from typing import Any

from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf.message import Message

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.foxglove_scene import SCENE_TOPIC, TF_TOPIC, FoxgloveScene
from swarmhil.bus.keys import Keys
from swarmhil.bus.optional import require
from swarmhil.bus.recorder import epoch_ns, message_type_for_key, parse_sample

log = logging.getLogger("swarmhil.foxglove")

LOOPBACK = "127.0.0.1"
DEFAULT_PORT = 8765


def ws_url(port: int) -> str:
    return f"ws://{LOOPBACK}:{port}"


class FoxgloveLive:
    """Samples of one run -> Foxglove channels on a WebSocket server (not thread-safe: one caller)."""

    def __init__(self, run: str, config: dict[str, Any] | None, port: int = DEFAULT_PORT) -> None:
        self._fg = foxglove = require("foxglove", "--viz foxglove")
        self.run = run
        self.keys = Keys(run)
        self.epoch_ns = epoch_ns(((config or {}).get("run") or {}).get("epoch_utc"))
        self.scene = FoxgloveScene(config)
        self.ctx = foxglove.Context()
        self._key_info: dict[str, tuple[type[Message] | None, str]] = {}
        self._channels: dict[str, Any] = {}
        self._schemas: dict[str, Any] = {}
        # The channels every run has exist before the server accepts a client, so its first
        # advertisement holds them: a channel made while a client was connecting could be missing
        # from both that client's first advertisement and the server's announcement of new channels
        # (a live client once saw the scene and transforms of a run and no truth).
        for topic, cls in (("truth", pb.Truth), (TF_TOPIC, FrameTransforms), (SCENE_TOPIC, SceneUpdate)):
            self._channel(topic, cls)
        self.server = foxglove.start_server(name=f"swarmhil {run}", host=LOOPBACK, port=int(port), context=self.ctx)
        self.port = self.server.port
        self.url = ws_url(self.port)
        self._last_t_ns = 0
        self.counts: dict[str, int] = {}
        self.rejected = 0
        self.flushes = 0

    def _schema(self, cls: type[Message]) -> Any:
        name = cls.DESCRIPTOR.full_name
        sch = self._schemas.get(name)
        if sch is None:
            from mcap_protobuf.schema import build_file_descriptor_set

            sch = self._schemas[name] = self._fg.Schema(name=name, encoding="protobuf",
                                                        data=build_file_descriptor_set(cls).SerializeToString())
        return sch

    def _channel(self, topic: str, cls: type[Message]) -> Any:
        ch = self._channels.get(topic)
        if ch is None:
            ch = self._channels[topic] = self._fg.Channel(topic, message_encoding="protobuf", schema=self._schema(cls),
                                                         context=self.ctx)
        return ch

    def _send(self, topic: str, cls: type[Message], payload: bytes, log_ns: int) -> None:
        self._channel(topic, cls).log(payload, log_time=log_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def ingest(self, key: str, payload: bytes) -> bool:
        """Send one sample and what derives from it; never asks for a flush (returns False)."""
        known = self._key_info.get(key)
        if known is None:
            known = self._key_info[key] = (message_type_for_key(self.keys, key), self.keys.topic(key))
        cls, topic = known
        msg, t_ns, reason = parse_sample(cls, payload)
        if reason or cls is None:
            self.rejected += 1   # the recording keeps it (UndecodableSample); the live view drops it
            return False
        if t_ns is not None:
            self._last_t_ns = max(self._last_t_ns, t_ns)
        log_ns = self.epoch_ns + max(self._last_t_ns if t_ns is None else t_ns, 0)
        self._send(topic, cls, payload, log_ns)
        for d_topic, d_cls, d_payload in self.scene.derive(cls, msg, topic, log_ns):
            self._send(d_topic, d_cls, d_payload, log_ns)
        return False

    def flush(self, final: bool = False) -> None:
        """Nothing is batched: every sample went out in ingest."""
        self.flushes += 1

    def close(self) -> None:
        for ch in self._channels.values():
            ch.close()
        self.server.stop()

    def stats(self) -> dict[str, Any]:
        return {"samples": dict(self.counts), "rejected": self.rejected, "flushes": self.flushes, "port": self.port,
                "url": self.url}
