"""Foxglove's own 3D messages from the truth, written by the recorder into every recording.

DESIGN.md "MCAP (contract)": besides the swarmhil.v1 messages, a recording carries
`foxglove.FrameTransforms` (topic `foxglove/tf`) and `foxglove.SceneUpdate` (topic
`foxglove/scene`), so Foxglove's 3D panel shows a run with no plugin.

- Frames: the scenario frame `lvlh` (x radial, y along-track, z cross-track) is the root; every
  body of the truth is a child frame named by its id, translated by its position and rotated by
  its attitude where the mission flies attitude, identity otherwise (`lvlh_attitude_wxyz`: a
  spacecraft's truth attitude is body -> the inertial frame aligned with LVLH at t = 0, turned here
  into body -> LVLH; a kinematic body's is already in the scenario frame).
- Scene: one entity per body in its own frame (`frame_locked`): a sphere for a spacecraft coloured
  by its agent's mode (`MODE_COLOURS`, the viewer's; the mode of the newest telemetry before this
  truth, so one step behind; blue before any, grey once dead, red while a `[[fault]]` on the
  `faults` topic strikes it: docs/faults.md), the body's shape for other bodies (`[[body]].shape` of the resolved config:
  an ellipsoid, or a list of spheres in the body frame; a small orange sphere without a shape),
  and its id as a text label; plus one entity `links` in `lvlh` with a line per ISL delivery
  seen since the previous truth (sender -> receiver).
- Log: every `swarmhil.v1.Event` (topics `event` and `faults`) also as a `foxglove.Log` (topic
  `foxglove/log`) for the Log panel.

`FoxgloveScene.derive` is the one place these messages are made from samples: the recorder
(bus/recorder.py) writes what it returns into the MCAP, the live Foxglove server
(dashboards/foxglove_live.py) sends the same over its WebSocket.
"""
from __future__ import annotations

import json
import math
import zlib
from typing import Any

import numpy as np

from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.bulk_wire import Area, Plans, Pool, Prepared, Rows, StringTable
from swarmhil.bus.truth_wire import _double, _string, varint

ROOT_FRAME = "lvlh"
TF_TOPIC = "foxglove/tf"
SCENE_TOPIC = "foxglove/scene"
LOG_TOPIC = "foxglove/log"
_WARN_EVENTS = ("agent_dead", "deadline_missed", "rejected_packet", "late_command", "lockstep_stall", "link_stall",
                "agent_restart", "agent_rejoin", "recorder_restart", "fault_start", "fault_end", "contact",
                "near_miss", "agent_paused", "agent_resumed")
SPACECRAFT_DIAMETER_M = 4.0  # display size (the truth has no spacecraft geometry)
BODY_DIAMETER_M = 6.0        # a body without a shape

_BLUE = Color(r=0.25, g=0.55, b=1.0, a=1.0)
_GREY = Color(r=0.5, g=0.5, b=0.5, a=0.6)
_ORANGE = Color(r=1.0, g=0.6, b=0.2, a=0.8)
_WHITE = Color(r=1.0, g=1.0, b=1.0, a=1.0)
_GREEN = Color(r=0.3, g=1.0, b=0.4, a=0.8)
_RED = Color(r=1.0, g=0.1, b=0.1, a=1.0)    # a spacecraft a [[fault]] strikes, while the fault lasts
_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)

# Colours (RGB) of modes and behaviours; unknown names get a stable hashed colour.
MODE_COLOURS: dict[str, tuple[int, int, int]] = {
    "collision_avoidance": (230, 57, 70),
    "attraction": (244, 162, 37),
    "alignment": (72, 191, 99),
    "alignment_drift": (155, 214, 96),
    "coast": (84, 140, 235),
    "search": (176, 120, 230),
    "chase": (244, 162, 37),
    "dock": (72, 191, 99),
    "drift-null": (40, 190, 205),
    "idle": (150, 150, 150),
    "none": (150, 150, 150),
    "fault": (255, 0, 200),
}


def mode_colour(name: str) -> tuple[int, int, int]:
    """Colour of a mode or behaviour label; `x_disabled` is a dimmed `x`."""
    if name in MODE_COLOURS:
        return MODE_COLOURS[name]
    if name.endswith("_disabled") and name[: -len("_disabled")] in MODE_COLOURS:
        return tuple(int(c * 0.45) for c in MODE_COLOURS[name[: -len("_disabled")]])  # type: ignore[return-value]
    h = zlib.crc32(name.encode())
    return (64 + h % 160, 64 + (h >> 8) % 160, 64 + (h >> 16) % 160)


def _mode_color(mode: str) -> Color:
    r, g, b = mode_colour(mode)
    return Color(r=r / 255.0, g=g / 255.0, b=b / 255.0, a=1.0)


def _timestamp(t_ns: int) -> Timestamp:
    return Timestamp(seconds=t_ns // 1_000_000_000, nanos=t_ns % 1_000_000_000)


def lvlh_attitude_wxyz(q_wxyz: np.ndarray, n_radps: float, t_s: float) -> np.ndarray:
    """Body -> LVLH attitude (..., 4) scalar-first, from the plant's body -> inertial one.

    plant/mission_world.py flies attitude in an inertial frame aligned with the scenario's LVLH at
    t = 0; the LVLH frame of a circular reference has turned by n t about +z since, so
    q_lvlh = q_z(-n t) (x) q_inertial (Hamilton), as missions/p000_capture/sense.py inertial_to_cw.
    """
    q = np.asarray(q_wxyz, float)
    h = -0.5 * float(n_radps) * float(t_s)
    c, s = math.cos(h), math.sin(h)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack((c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w), axis=-1)


def _rotation(body: Any, n_radps: float = 0.0, t_s: float = 0.0) -> Quaternion:
    """The frame rotation of a truth body (spacecraft: turned into LVLH), identity without attitude."""
    if body.HasField("attitude"):
        q = body.attitude
        n = math.sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z)
        if n > 0 and math.isfinite(n):
            w, x, y, z = q.w / n, q.x / n, q.y / n, q.z / n
            if body.kind in ("", "spacecraft") and n_radps:
                w, x, y, z = lvlh_attitude_wxyz(np.array([w, x, y, z]), n_radps, t_s).tolist()
            return Quaternion(x=x, y=y, z=z, w=w)
    return _IDENTITY


def _shape_primitives(shape: dict[str, Any] | None) -> list[SpherePrimitive]:
    if not shape:
        return [SpherePrimitive(pose=Pose(orientation=_IDENTITY), size=Vector3(x=BODY_DIAMETER_M, y=BODY_DIAMETER_M,
                                                                              z=BODY_DIAMETER_M), color=_ORANGE)]
    if shape.get("kind") == "ellipsoid":
        a, b, c = (2.0 * float(x) for x in shape["semi_axes_m"])
        return [SpherePrimitive(pose=Pose(orientation=_IDENTITY), size=Vector3(x=a, y=b, z=c), color=_ORANGE)]
    out = []
    for centre, r in zip(shape.get("centers_m", []), shape.get("radii_m", [])):
        d = 2.0 * float(r)
        out.append(SpherePrimitive(pose=Pose(position=Vector3(x=centre[0], y=centre[1], z=centre[2]), orientation=_IDENTITY),
                                   size=Vector3(x=d, y=d, z=d), color=_ORANGE))
    return out


class FoxgloveScene:
    """Turns each decoded Truth into (FrameTransforms, SceneUpdate) payloads."""

    def __init__(self, config: dict[str, Any] | None = None) -> None:
        self.shapes: dict[str, dict[str, Any] | None] = {}
        for b in (config or {}).get("body") or []:
            if isinstance(b, dict) and "id" in b:
                self.shapes[str(b["id"])] = b.get("shape")
        self._links: set[tuple[str, str]] = set()
        self._modes: dict[str, str] = {}
        self._faulty: dict[str, int] = {}  # spacecraft id -> [[fault]]s active on it (the `faults` topic)
        self._templates: dict[tuple[str, str, bool, str], SceneEntity] = {}
        self._template_bytes: dict[int, bytes] = {}  # id of a template (kept in _templates) -> its bytes
        self._tf = _Transforms()
        self._lines = _Lines()
        self._link_rows: dict[tuple[frozenset[tuple[str, str]], tuple[str, ...]], np.ndarray] = {}
        self._body_templates: dict[tuple, list[bytes]] = {}  # ((ids, kinds, alive, modes, faults), timestamp length) -> pieces

    def _template(self, body_id: str, kind: str, alive: bool) -> SceneEntity:
        """The entity of a body without its timestamp (built once per body, state and mode)."""
        mode = self._modes.get(body_id, "")
        faulty = self._faulty.get(body_id, 0) > 0
        key = (body_id, kind, alive, mode + "\0fault" * faulty)
        ent = self._templates.get(key)
        if ent is None:
            ent = SceneEntity(frame_id=body_id, id=body_id, frame_locked=True)
            if kind in ("", "spacecraft"):
                d = SPACECRAFT_DIAMETER_M
                colour = _GREY if not alive else _RED if faulty else _mode_color(mode) if mode else _BLUE
                ent.spheres.append(SpherePrimitive(pose=Pose(orientation=_IDENTITY), size=Vector3(x=d, y=d, z=d),
                                                   color=colour))
            else:
                ent.spheres.extend(_shape_primitives(self.shapes.get(body_id)))
            ent.texts.append(TextPrimitive(pose=Pose(position=Vector3(x=0.0, y=0.0, z=6.0), orientation=_IDENTITY),
                                           billboard=True, font_size=12.0, scale_invariant=True, color=_WHITE,
                                           text=body_id))
            ent.metadata.add(key="kind", value=kind or "spacecraft")
            self._templates[key] = ent
        return ent

    def _serialized_template(self, body_id: str, kind: str, alive: bool) -> bytes:
        """`_template`'s entity serialised (the entity of the current mode and faults, kept with its bytes)."""
        ent = self._template(body_id, kind, alive)
        data = self._template_bytes.get(id(ent))
        if data is None:
            data = self._template_bytes[id(ent)] = ent.SerializeToString()
        return data

    def saw_fault(self, event: Any) -> None:
        """A [[fault]]'s start or end (plant/faults.py): its target spacecraft are drawn red meanwhile."""
        try:
            targets = json.loads(event.detail).get("targets") or []
        except (ValueError, AttributeError):
            return
        step = {"fault_start": 1, "fault_end": -1}.get(event.kind, 0)
        for sid in targets:
            self._faulty[str(sid)] = max(0, self._faulty.get(str(sid), 0) + step)

    def saw_delivery(self, src: str, dst: str) -> None:
        """An ISL delivery src -> dst (drawn with the next truth)."""
        if src and dst:
            self._links.add((src, dst))

    def saw_modes(self, ids: list[str], modes: list[str]) -> None:
        """The modes of the agents' telemetry (`derive` of each one's Telemetry: an empty mode is not kept)."""
        if "" not in modes:
            self._modes.update(zip(ids, modes))
            return
        for sid, mode in zip(ids, modes):
            if mode:
                self._modes[sid] = mode

    # the message classes `derive` looks at: a recorder need not decode a sample of any other class
    DERIVES_FROM: frozenset[type] = frozenset({pb.Truth, pb.Event, pb.IslPacket, pb.Telemetry})

    def derive(self, cls: type, msg: Any, topic: str, t_ns: int) -> list[tuple[str, type, bytes]]:
        """Foxglove messages made from one decoded sample of `topic` (log time t_ns since 1970):
        (topic, class, payload) to write or send; an ISL delivery and an agent's mode (telemetry) are
        kept for the next truth."""
        if msg is None:
            return []
        if cls is pb.Truth:
            tf, scene = self.from_truth(msg, t_ns)
            return [(TF_TOPIC, FrameTransforms, tf), (SCENE_TOPIC, SceneUpdate, scene)]
        if cls is pb.Event:
            if topic == "faults":
                self.saw_fault(msg)
            return [(LOG_TOPIC, Log, event_log(msg, t_ns))]
        if cls is pb.IslPacket and topic.startswith("isl/rx/"):
            self.saw_delivery(msg.src, topic[len("isl/rx/"):])
        elif cls is pb.Telemetry and msg.mode and topic.startswith("sc/") and topic.endswith("/tm"):
            self.saw_modes([topic[3:-3]], [msg.mode])   # sc/<id>/tm: the sphere's colour from the next truth on
        return []

    def from_truth(self, truth: Any, t_ns: int) -> tuple[bytes, bytes]:
        """(FrameTransforms, SceneUpdate) of a decoded Truth."""
        bodies = truth.bodies
        ids, kinds, alive = [b.id for b in bodies], [b.kind for b in bodies], [b.alive for b in bodies]
        pos = np.array([(q.x, q.y, q.z) for q in (b.position_m for b in bodies)], dtype=float).reshape(-1, 3)
        rotations = None
        if any(b.HasField("attitude") for b in bodies):  # the frame rotations (identity without attitude)
            n_radps, t_s = truth.mean_motion_radps, truth.header.t
            rotations = [_rotation(b, n_radps, t_s).SerializeToString() if b.HasField("attitude") else None for b in bodies]
        return self.from_bodies(ids, kinds, alive, pos, t_ns, rotations)

    def from_bodies(self, ids: list[str], kinds: list[str], alive: list[bool], position_m: np.ndarray, t_ns: int,
                    rotations: list[bytes | None] | None = None) -> tuple[bytes, bytes]:
        """(FrameTransforms, SceneUpdate) of the truth's bodies: ids, kinds, alive, positions (N, 3),
        and each one's serialised frame rotation (None: the identity; `rotations` None: all). What
        `from_truth` gives for the Truth that carries them (a batch run's recorder passes its
        plant's arrays: bus/recorder.py `next_truth`)."""
        seconds, nanos = divmod(t_ns, 1_000_000_000)
        # SceneUpdate's entities (field 2) as bytes: each entity is its template's fields after its
        # timestamp (field 1; protobuf writes fields in number order), so one serialised template per
        # body and state is reused; tests/test_foxglove_recording.py checks the bytes against the entities
        # built field by field. `head`: the timestamp field, Timestamp(seconds, nanos) (both >= 0 here)
        head = _field(0x0A, (b"\x08" + varint(seconds) if seconds else b"") + (b"\x10" + varint(nanos) if nanos else b""))
        modes, faulty = self._modes, self._faulty
        state = (tuple(ids), tuple(kinds), tuple(alive), tuple([modes.get(i, "") for i in ids]),
                 tuple([faulty.get(i, 0) > 0 for i in ids]) if faulty else ())
        key = (state, len(head))
        pieces = self._body_templates.get(key)
        if pieces is None:  # (every body's entity in this state around the timestamp's place, kept: states recur)
            if len(self._body_templates) > 4096:
                self._body_templates.clear()
            templates = [self._serialized_template(i, k, a) for i, k, a in zip(ids, kinds, alive)]
            heads = [b"\x12" + varint(len(head) + len(t)) for t in templates]  # SceneUpdate.entities: tag, length
            pieces = self._body_templates[key] = [a + b for a, b in zip([b""] + templates, heads + [b""])]
        # entity i is heads[i] + head + templates[i]: the pieces joined by the timestamp
        entities = [head.join(pieces)] if len(pieces) > 1 else []
        if not self._links:  # SceneEntity(timestamp, frame_id=ROOT_FRAME, id="links", frame_locked=False)
            entities.append(_entity_field(head + _LINKS_FIELDS))
            return self._transforms(ids, position_m, seconds, nanos, head, rotations), b"".join(entities)
        # SceneEntity(timestamp, frame_id=ROOT_FRAME, id="links", frame_locked=False, lines=[LINE_LIST of the
        # deliveries' ends, src then dst, in sorted order]) as bytes: the line's fields around its points
        # (field 5, Point3 each, from a plan: `_Lines`); tests/test_foxglove_recording.py checks them
        key_l = (frozenset(self._links), tuple(ids))
        rows = self._link_rows.get(key_l)
        if rows is None:  # (the bodies' rows of the links' ends, src then dst, in sorted order: kept, they recur)
            index = {sid: i for i, sid in enumerate(ids)}
            ends = [(index[a], index[b]) for a, b in sorted(self._links) if a in index and b in index]
            if len(self._link_rows) >= 1024:
                self._link_rows.clear()
            rows = self._link_rows[key_l] = np.array(ends, dtype=np.int64).reshape(-1)
        self._links.clear()
        links = head + _LINKS_FIELDS
        if len(rows):
            points = self._lines.encode(position_m[rows])
            links += _field(0x5A, _LINE_HEAD + points + _LINE_TAIL)  # SceneEntity.lines (field 11)
        entities.append(_entity_field(links))
        return self._transforms(ids, position_m, seconds, nanos, head, rotations), b"".join(entities)

    def _transforms(self, ids: list[str], position_m: np.ndarray, seconds: int, nanos: int, head: bytes,
                    rotations: list[bytes | None] | None) -> bytes:
        """FrameTransforms' transforms (field 1) as bytes: each FrameTransform's fields in number order
        (timestamp, parent, child, translation, rotation), the same bytes as the message built field
        by field (tests/test_foxglove_recording.py); without rotations, from the layout's plan (bus/bulk_wire.py)."""
        if rotations is None:
            return self._tf.encode(ids, position_m, seconds, nanos)
        tf_head = head + _PARENT_FIELD  # (the timestamp is FrameTransform's field 1 too)
        out = []
        for sid, (x, y, z), rot in zip(ids, position_m.tolist(), rotations):
            tr = _double(0x09, x) + _double(0x11, y) + _double(0x19, z)
            out.append(_field(0x0A, tf_head + _string(0x1A, sid) + _field(0x22, tr)
                              + (_IDENTITY_FIELD if rot is None else _field(0x2A, rot))))
        return b"".join(out)


class _Transforms:
    """FrameTransforms of bodies with identity rotations from arrays, one plan per layout (the ids,
    which coordinates are +0.0, the timestamp's varints' lengths: bus/bulk_wire.py)."""

    def __init__(self) -> None:
        self.pool = Pool()
        self.plans = Plans(self.pool)
        self._tables: dict[tuple[str, ...], tuple[StringTable, bytes]] = {}  # ids -> their table, key

    def encode(self, ids: list[str], position_m: np.ndarray, seconds: int, nanos: int) -> bytes:
        n = len(ids)
        if n == 0:
            return b""
        key_ids = tuple(ids)
        got = self._tables.get(key_ids)
        if got is None:
            got = self._tables[key_ids] = (StringTable(0x1A, ids), b"ids%d" % len(self._tables))
        table, ids_key = got
        area = Area(position_m)
        sec, nan = area.varint(seconds), area.varint(nanos)
        key = (ids_key, *area.key)

        def build() -> tuple[np.ndarray, np.ndarray]:
            pool = self.pool
            ts = Rows(n, pool)
            for tag, (v_ids, lens, present) in ((0x08, sec), (0x10, nan)):
                ts.varints(tag, np.broadcast_to(v_ids, (n, v_ids.shape[1])), np.broadcast_to(lens, (n,)),
                           np.broadcast_to(present, (n,)))
            present, v = area.double_ids(0, (n, 3))
            t = Rows(n, pool).nested(0x0A, ts).const(_PARENT_FIELD).strings(table, np.arange(n))
            t.nested(0x22, Rows(n, pool).doubles((0x09, 0x11, 0x19), present, v)).const(_IDENTITY_FIELD)
            return Rows(n, pool).nested(0x0A, t).plan()

        return Prepared(key, area, self.plans, build).encode()[0]


class _Lines:
    """LinePrimitive.points (field 5: Point3 x, y, z, +0.0 omitted) of (P, 3) points, one plan per
    layout (the count and which coordinates are +0.0: bus/bulk_wire.py)."""

    def __init__(self) -> None:
        self.pool = Pool()
        self.plans = Plans(self.pool)

    def encode(self, points: np.ndarray) -> bytes:
        n = len(points)
        area = Area(points)
        key = (b"%d" % n, *area.key)

        def build() -> tuple[np.ndarray, np.ndarray]:
            present, v = area.double_ids(0, (n, 3))
            return Rows(n, self.pool).nested(0x2A, Rows(n, self.pool).doubles((0x09, 0x11, 0x19), present, v)).plan()

        return Prepared(key, area, self.plans, build).encode()[0]


def _entity_field(entity: bytes) -> bytes:
    """One serialised SceneEntity as SceneUpdate's field 2 (`entities`): tag, varint length, bytes."""
    return b"\x12" + varint(len(entity)) + entity


def _field(tag: int, data: bytes) -> bytes:
    """A length-delimited field (a sub-message that is present, even when empty)."""
    return bytes((tag,)) + varint(len(data)) + data


_PARENT_FIELD = _string(0x12, ROOT_FRAME)  # FrameTransform.parent_frame_id
_IDENTITY_FIELD = _field(0x2A, _IDENTITY.SerializeToString())  # FrameTransform.rotation
_LINKS_FIELDS = _string(0x12, ROOT_FRAME) + _string(0x1A, "links")  # the `links` entity's fields after its timestamp, without lines
# the links' LinePrimitive: its fields before the points (type, pose, thickness, scale_invariant) and after them (color)
_LINE_HEAD = LinePrimitive(type=LinePrimitive.LINE_LIST, pose=Pose(orientation=_IDENTITY), thickness=1.5,
                           scale_invariant=True).SerializeToString()
_LINE_TAIL = LinePrimitive(color=_GREEN).SerializeToString()


def event_log(event: Any, t_ns: int) -> bytes:
    """A swarmhil.v1.Event as foxglove.Log (faults as WARNING, the rest INFO)."""
    level = Log.WARNING if event.kind in _WARN_EVENTS else Log.INFO
    text = f"{event.kind} {event.subject}".strip() + (f": {event.detail}" if event.detail else "")
    return Log(timestamp=_timestamp(t_ns), level=level, message=text, name=event.header.source).SerializeToString()
