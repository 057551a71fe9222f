"""Encoding, decoding and validation of swarmhil.v1 messages.

A payload that does not decode, carries a non-finite number, or names an id the receiver does
not know is rejected with `RejectedPacket` (a precise reason); receivers count rejections in a
`Rejections` and carry on.
"""
from __future__ import annotations

import logging
import math
import re
from collections import Counter
from typing import Iterable, Sequence, TypeVar

import numpy as np
from google.protobuf.message import DecodeError, Message

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.keys import parse_topic, split_topic

M = TypeVar("M", bound=Message)
log = logging.getLogger("swarmhil.codec")

# Message type of each key kind (see bus/keys.py Keys.parse).
TYPE_OF_KIND: dict[str, type[Message]] = {
    "clock": pb.Tick,
    "sync": pb.Tick,
    "truth": pb.Truth,
    "event": pb.Event,
    "faults": pb.Event,  # a [[fault]]'s start and end (plant/faults.py)
    "link_stats": pb.LinkStats,
    "act": pb.ActuatorCommand,
    "tm": pb.Telemetry,
    "isl_tx": pb.IslPacket,
    "isl_rx": pb.IslPacket,
}
TYPE_OF_SENSE: dict[str, type[Message]] = {"rel": pb.RelStimulus, "scene": pb.SceneStimulus}


def sense_type(kind: str) -> type[Message]:
    """Message type of a sensing kind: `rel` and `scene` have their own; every other (mission)
    kind carries `Measurements` (plant/sensing/)."""
    return TYPE_OF_SENSE.get(kind, pb.Measurements)


def message_type_of_topic(topic: str) -> type[Message] | None:
    """Message type of a key (`swarm/<run>/...`) or MCAP topic (`truth`, `sc/sc01/act`), None for a
    key outside the contract or one without payload (liveliness tokens). bus/keys.json is this map
    as data (bus/keys_json.py)."""
    try:
        kind, _id, sense = parse_topic(split_topic(topic)[1])
    except ValueError:
        return None
    if kind == "sense":
        return sense_type(sense or "")
    if kind == "tm_image":
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        return CompressedImage
    return TYPE_OF_KIND.get(kind)


PROTOBUF_ENCODING = "application/protobuf"


def encoding_of_key(key: str) -> str | None:
    """The Zenoh encoding of a key's samples: `application/protobuf;<message type>` (DESIGN.md)."""
    cls = message_type_of_topic(key)
    return None if cls is None else f"{PROTOBUF_ENCODING};{cls.DESCRIPTOR.full_name}"


def measurements_to_dict(msg: "pb.Measurements | pb.Telemetry") -> dict[str, np.ndarray]:
    """Named arrays (`items`) of a Measurements or Telemetry message: key `name`, or `name/subject`."""
    out: dict[str, np.ndarray] = {}
    for m in msg.items:
        a = np.asarray(m.values, dtype=float)
        if len(m.shape):
            a = a.reshape(tuple(m.shape))
        out[f"{m.name}/{m.subject}" if m.subject else m.name] = a
    return out


class NamedRows(Sequence[dict[str, np.ndarray]]):
    """The named arrays of R observers kept as one (R, ...) array per name: observer r's are
    `{name: rows[name][r]}` (views, in the order of `rows`), made when asked for. What a batch
    sensing form gives instead of R dicts (issue 29: a reader of the arrays, such as paper 001's
    batch step, takes `rows` as they are; any other reader sees the dicts)."""

    __slots__ = ("rows", "_n")

    def __init__(self, rows: dict[str, np.ndarray], n: int) -> None:
        self.rows = rows
        self._n = n

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, r: int) -> dict[str, np.ndarray]:  # type: ignore[override]
        if isinstance(r, slice):
            return [self[i] for i in range(*r.indices(self._n))]  # type: ignore[return-value]
        if not -self._n <= r < self._n:
            raise IndexError(r)
        return {name: a[r] for name, a in self.rows.items()}


def add_measurement(msg: "pb.Measurements | pb.Telemetry", name: str, values: Sequence[float] | np.ndarray,
                    subject: str = "") -> None:
    """Append one named array (any shape) to a Measurements or Telemetry message."""
    a = np.asarray(values, dtype=float)
    msg.items.add(name=name, subject=subject, values=a.ravel().tolist(), shape=list(a.shape) if a.ndim != 1 else [])


class RejectedPacket(ValueError):
    """A received payload that must not be acted on."""


def vec(v: Sequence[float] | np.ndarray) -> pb.Vector3:
    return pb.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def arr(v: pb.Vector3) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def sim_time_ns(t: float) -> int | None:
    """A header time t [s] as the recorder's log time offset [ns]; None when it is not usable
    (NaN, inf, beyond 1e12 s): such a sample keeps the last time (docs/architecture.md)."""
    return int(round(t * 1e9)) if t == t and abs(t) < 1e12 else None


def header(run: str, source: str, step: int, t: float, seq: int) -> pb.Header:
    return pb.Header(run=run, source=source, step=step, t=t, seq=seq)


def _non_finite_field(msg: Message, path: str = "") -> str | None:
    """Name of the first float/double field that holds NaN or inf, or None."""
    for fd, value in msg.ListFields():
        name = f"{path}{fd.name}"
        if fd.type == fd.TYPE_MESSAGE:
            items = value if fd.is_repeated else [value]
            for i, item in enumerate(items):
                bad = _non_finite_field(item, f"{name}[{i}]." if fd.is_repeated else f"{name}.")
                if bad:
                    return bad
        elif fd.type in (fd.TYPE_DOUBLE, fd.TYPE_FLOAT):
            items = value if fd.is_repeated else [value]
            # a finite sum means every item is finite (NaN and inf propagate); only a non-finite sum
            # (a bad item, or finite ones that overflow) walks the items (issue 29: landmark arrays)
            if math.isfinite(sum(items)):
                continue
            for x in items:
                if not math.isfinite(x):
                    return f"{name}={x}"
    return None


# A double is NaN or infinite when its exponent bits are all ones: in its 8 little-endian wire bytes,
# byte 6 >= 0xF0 and byte 7 in {0x7F, 0xFF}. A payload with no such adjacent pair anywhere cannot
# hold a non-finite double, so the field walk below (exact, but Python per field) is skipped. A
# 32-bit float (bytes 2, 3: >= 0x80, then 0x7F/0xFF) needs the wider pattern. Same verdicts, the
# screen only avoids the walk (issue 16: it was 8 % of an in-process run).
_MAYBE_NONFINITE_DOUBLE = re.compile(rb"[\xf0-\xff][\x7f\xff]")
_MAYBE_NONFINITE_FLOAT = re.compile(rb"[\x80-\xff][\x7f\xff]")
_SCREEN: dict[str, re.Pattern[bytes]] = {}


def _has_float32(desc, seen: set[str] | None = None) -> bool:  # type: ignore[no-untyped-def]
    seen = set() if seen is None else seen
    if desc.full_name in seen:
        return False
    seen.add(desc.full_name)
    for fd in desc.fields:
        if fd.type == fd.TYPE_FLOAT:
            return True
        if fd.type == fd.TYPE_MESSAGE and _has_float32(fd.message_type, seen):
            return True
    return False


def _screen(cls: type[Message]) -> re.Pattern[bytes]:
    name = cls.DESCRIPTOR.full_name
    pat = _SCREEN.get(name)
    if pat is None:
        pat = _SCREEN[name] = _MAYBE_NONFINITE_FLOAT if _has_float32(cls.DESCRIPTOR) else _MAYBE_NONFINITE_DOUBLE
    return pat


def decode(cls: type[M], payload: bytes, *, run: str | None = None) -> M:
    """Parse and validate one message; raise RejectedPacket with the reason."""
    msg = cls()
    try:
        msg.ParseFromString(payload)
    except (DecodeError, RuntimeWarning, ValueError) as exc:
        raise RejectedPacket(f"{cls.DESCRIPTOR.name}: payload of {len(payload)} B does not decode ({exc})") from None
    bad = _non_finite_field(msg) if _screen(cls).search(payload) else None
    if bad:
        raise RejectedPacket(f"{cls.DESCRIPTOR.name}: non-finite value {bad}")
    if run is not None and "header" in cls.DESCRIPTOR.fields_by_name:
        # a message without a header cannot be checked for run, source or step: never act on it
        if not msg.HasField("header"):  # type: ignore[attr-defined]
            raise RejectedPacket(f"{cls.DESCRIPTOR.name}: no header")
        if msg.header.run != run:  # type: ignore[attr-defined]
            raise RejectedPacket(f"{cls.DESCRIPTOR.name}: header.run {msg.header.run!r} is not {run!r}")  # type: ignore[attr-defined]
    return msg


def check_complete_command(cmd: "pb.ActuatorCommand") -> None:
    """An agent always sends header, accel_mps2 and controller (fields 1-3, serialized in that
    order): a command cut short at a field boundary lacks one of them and is rejected. (Only the
    trailing optional fields cannot be told apart from absent ones; the access control keeps anyone
    but the agent itself off its `act` key.)"""
    if not cmd.HasField("accel_mps2"):
        raise RejectedPacket("ActuatorCommand: no accel_mps2 (truncated?)")
    if not cmd.controller:
        raise RejectedPacket("ActuatorCommand: no controller name (truncated?)")


def command_rejection(cmd: "pb.ActuatorCommand", key_id: str, run: str) -> str | None:
    """Why a decoded ActuatorCommand on spacecraft `key_id`'s `act` key of `run` must not be acted
    on, or None: no header, another run's header.run, a header.source other than the key's
    spacecraft, or a command cut short (`check_complete_command`). The plant (which rejects it and
    publishes an Event "rejected_command") and the recorder (which records it as a RejectedSample)
    both ask here, so the recording and the flight agree."""
    if not cmd.HasField("header"):
        return "ActuatorCommand: no header"
    if cmd.header.run != run:
        return f"ActuatorCommand: header.run {cmd.header.run!r} is not {run!r}"
    if cmd.header.source != key_id:
        return f"header.source {cmd.header.source!r} does not match key id {key_id!r}"
    try:
        check_complete_command(cmd)
    except RejectedPacket as exc:
        return str(exc)
    return None


def check_known(value: str, known: Iterable[str], what: str) -> None:
    if value not in known:
        raise RejectedPacket(f"unknown {what} {value!r}")


class Rejections:
    """Counts rejected packets by reason class and logs the first few of each in full."""

    def __init__(self, owner: str, log_first: int = 5) -> None:
        self.owner = owner
        self.total = 0
        self.by_key: Counter[str] = Counter()
        self.log_first = log_first

    def add(self, key: str, reason: str) -> None:
        self.total += 1
        self.by_key[key] += 1
        if self.by_key[key] <= self.log_first:
            log.warning("%s rejected packet on %s: %s", self.owner, key, reason)
