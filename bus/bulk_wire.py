"""Protobuf wire bytes of many messages at once from arrays: the batch mode's packets (every agent's
stimulus, command and telemetry of a step) without a protobuf message per packet.

A message of fixed field order is a row of *parts*; each part is at most `w` bytes, and a row keeps
the first `lens[row]` bytes of each of its parts: a field that proto3's implicit presence omits
(a double whose 64 bits are all zero, i.e. +0.0; an integer 0; an empty string) is a part of
length 0. `Rows.encode` gathers every row's kept bytes in one numpy mask over the (rows, Σ w)
matrix of all parts, so the bytes of R messages are one concatenated buffer and R + 1 offsets.
Nested messages (`Rows.nested`) are the sub-rows' parts behind a head of tag + varint length (a
sub-message that was assigned is present even when empty, as protobuf writes it); repeated
sub-messages of variable count per row (a stimulus's neighbours, a telemetry's decisions) are
encoded as their own rows first and enter the message as one `segments` part of each row.

Wire format (protocol buffers encoding): a field is a tag byte (number << 3 | wire type) then,
for wire type 1 (fixed64) 8 little-endian bytes, for wire type 2 a varint length then the
bytes, for wire type 0 a varint. Packed repeated doubles: tag, varint 8 n, the n doubles. The
bytes equal protobuf's `SerializeToString` of the same values (tests/test_bulk_wire.py checks
them against the protobuf library on random values with zeros, -0.0, NaN and inf).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

_VARINT_MAX = 10  # bytes of a 64-bit varint


def varint_bytes(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Base-128 varints of non-negative integers (n,): bytes (n, 10) and each one's length (>= 1)."""
    v = np.asarray(values, dtype=np.uint64)
    n = len(v)
    out = np.zeros((n, _VARINT_MAX), dtype=np.uint8)
    shifts = (7 * np.arange(_VARINT_MAX)).astype(np.uint64)
    groups = (v[:, None] >> shifts[None, :]) & np.uint64(0x7F)  # 7-bit groups, least significant first
    # length: 1 + the index of the highest non-zero group (a zero is one byte)
    nz = groups != 0
    lens = np.where(nz.any(axis=1), _VARINT_MAX - np.argmax(nz[:, ::-1], axis=1), 1)
    more = np.arange(_VARINT_MAX)[None, :] < (lens[:, None] - 1)  # continuation bit on all but the last
    out[:] = groups.astype(np.uint8) | (more.astype(np.uint8) << 7)
    return out, lens


class StringTable:
    """Length-delimited fields of fixed strings (tag, varint length, UTF-8), one row per string; an
    empty string is a field of length 0 (implicit presence)."""

    def __init__(self, tag: int, strings: Sequence[str]) -> None:
        enc = []
        for s in strings:
            b = s.encode()
            v, n = varint_bytes(np.array([len(b)]))
            enc.append(bytes((tag,)) + v[0, :n[0]].tobytes() + b if b else b"")
        self.width = max([len(e) for e in enc] + [1])
        self.bytes = np.zeros((len(enc), self.width), dtype=np.uint8)
        for i, e in enumerate(enc):
            self.bytes[i, :len(e)] = np.frombuffer(e, dtype=np.uint8)
        self.lens = np.array([len(e) for e in enc], dtype=np.int64)
        self.index = {s: i for i, s in enumerate(strings)}


class Rows:
    """The fields of n messages of one layout, in field order (module docstring)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []  # (n, w) uint8 bytes, (n,) kept lengths

    def raw(self, data: np.ndarray, lens: np.ndarray) -> "Rows":
        self.parts.append((data, np.asarray(lens, dtype=np.int64)))
        return self

    def const(self, b: bytes) -> "Rows":
        """The same bytes in every row."""
        if b:
            self.raw(np.broadcast_to(np.frombuffer(b, dtype=np.uint8), (self.n, len(b))),
                     np.full(self.n, len(b), dtype=np.int64))
        return self

    def doubles(self, tags: Sequence[int], values: np.ndarray) -> "Rows":
        """Double fields (wire type 1) with tags `tags`, values (n, len(tags)): each written when
        its bits are not all zero (-0.0 and NaN are written, +0.0 is not)."""
        k = len(tags)
        v = np.ascontiguousarray(values, dtype=np.float64).reshape(self.n, k)
        bits = v.view(np.uint64)
        data = np.empty((self.n, k, 9), dtype=np.uint8)
        data[:, :, 0] = np.asarray(tags, dtype=np.uint8)
        data[:, :, 1:] = v.view(np.uint8).reshape(self.n, k, 8)
        present = (bits != 0) * 9
        for i in range(k):
            self.parts.append((data[:, i, :], present[:, i]))
        return self

    def packed_doubles(self, tag: int, values: np.ndarray) -> "Rows":
        """A packed repeated double field of the same count k in every row (written when k > 0)."""
        v = np.ascontiguousarray(values, dtype=np.float64).reshape(self.n, -1)
        k = v.shape[1]
        if k == 0:
            return self
        head, hl = varint_bytes(np.array([8 * k]))
        self.const(bytes((tag,)) + head[0, :hl[0]].tobytes())
        return self.raw(v.view(np.uint8).reshape(self.n, 8 * k), np.full(self.n, 8 * k, dtype=np.int64))

    def uint(self, tag: int, values: np.ndarray) -> "Rows":
        """An unsigned varint field (wire type 0), omitted where 0."""
        v, lens = varint_bytes(np.broadcast_to(np.asarray(values, dtype=np.uint64), (self.n,)))
        data = np.empty((self.n, 1 + _VARINT_MAX), dtype=np.uint8)
        data[:, 0] = tag
        data[:, 1:] = v
        return self.raw(data, np.where(np.broadcast_to(values, (self.n,)) != 0, lens + 1, 0))

    def strings(self, table: StringTable, idx: np.ndarray) -> "Rows":
        """Row i's string field is table row idx[i]."""
        idx = np.broadcast_to(np.asarray(idx, dtype=np.int64), (self.n,))
        return self.raw(table.bytes[idx], table.lens[idx])

    def length(self) -> np.ndarray:
        """Each row's encoded length."""
        total = np.zeros(self.n, dtype=np.int64)
        for _d, lens in self.parts:
            total += lens
        return total

    def head(self, tag: int, lengths: np.ndarray) -> "Rows":
        """The head of a length-delimited field: tag, varint length."""
        v, lens = varint_bytes(lengths)
        data = np.empty((self.n, 1 + _VARINT_MAX), dtype=np.uint8)
        data[:, 0] = tag
        data[:, 1:] = v
        return self.raw(data, lens + 1)

    def nested(self, tag: int, sub: "Rows") -> "Rows":
        """A sub-message field (present even when empty) whose fields are `sub`'s."""
        self.head(tag, sub.length())
        self.parts.extend(sub.parts)
        return self

    def segments(self, blob: bytes | np.ndarray, starts: np.ndarray, lens: np.ndarray) -> "Rows":
        """Row i gets blob[starts[i]:starts[i] + lens[i]] (fields already encoded)."""
        b = np.frombuffer(blob, dtype=np.uint8) if isinstance(blob, (bytes, bytearray)) else blob
        lens = np.asarray(lens, dtype=np.int64)
        w = int(lens.max()) if self.n else 0
        if w == 0:
            return self
        cols = np.asarray(starts, dtype=np.int64)[:, None] + np.arange(w)[None, :]
        return self.raw(b[np.minimum(cols, len(b) - 1)], lens)

    def encode(self) -> tuple[bytes, np.ndarray]:
        """Every row's bytes, concatenated in row order, and the row offsets (n + 1,)."""
        ends = np.zeros(self.n + 1, dtype=np.int64)
        parts = [(d, lens) for d, lens in self.parts if d.shape[1]]
        if not parts or self.n == 0:
            return b"", ends
        data = np.concatenate([d for d, _ in parts], axis=1)
        widths = np.array([d.shape[1] for d, _ in parts])
        lens = np.stack([lens for _, lens in parts], axis=1)  # (n, parts)
        col = np.arange(data.shape[1]) - np.repeat(np.cumsum(widths) - widths, widths)  # position within its part
        keep = col[None, :] < np.repeat(lens, widths, axis=1)
        np.cumsum(lens.sum(axis=1), out=ends[1:])
        return data[keep].tobytes(), ends


class StringCache:
    """A StringTable that grows: `indices(strings)` gives each string's row (new strings are added)."""

    def __init__(self, tag: int, strings: Sequence[str] = ()) -> None:
        self.tag = tag
        self.strings: list[str] = []
        self.table = StringTable(tag, [])
        self.indices(strings)

    def indices(self, strings: Sequence[str]) -> np.ndarray:
        idx = self.table.index
        if any(s not in idx for s in strings):
            self.strings += [s for s in dict.fromkeys(strings) if s not in idx]
            self.table = StringTable(self.tag, self.strings)
            idx = self.table.index
        return np.array([idx[s] for s in strings], dtype=np.int64)

    def rows(self, strings: Sequence[str]) -> tuple[StringTable, np.ndarray]:
        """(the table, each string's row in it): a `Rows.strings` argument."""
        idx = self.indices(strings)
        return self.table, idx


_VEC3 = (0x09, 0x11, 0x19)  # Vector3 x, y, z


def vector3(rows: Rows, tag: int, values: np.ndarray) -> Rows:
    """A Vector3 field that was assigned (present), values (n, 3)."""
    return rows.nested(tag, Rows(rows.n).doubles(_VEC3, values))


def header_rows(n: int, run_source: bytes, step: int, t: float, seq: np.ndarray,
                sources: tuple[StringTable, np.ndarray] | None = None) -> Rows:
    """The fields of n `swarmhil.v1.Header`s: `run_source` the run (and source, when it is the same
    for all) fields' bytes; `sources` (table, row index) the source of each row otherwise."""
    h = Rows(n).const(run_source)
    if sources is not None:
        h.strings(*sources)
    return h.uint(0x18, np.full(n, step, dtype=np.uint64)).doubles((0x21,), np.full((n, 1), t)).uint(0x28, seq)


def split(blob: bytes, ends: np.ndarray) -> list[bytes]:
    """The rows of an `encode` result as separate bytes."""
    e = ends.tolist()
    return [blob[a:b] for a, b in zip(e[:-1], e[1:])]


def rel_stimuli(headers: Rows, u_rad: float, offsets: np.ndarray, ids: StringTable, neighbour: np.ndarray,
                rel_position_m: np.ndarray, rel_velocity_mps: np.ndarray) -> tuple[bytes, np.ndarray]:
    """`swarmhil.v1.RelStimulus` of R observers (plant/sensing/builtin.py RelKind.stimuli): header,
    u_rad, then neighbours offsets[r]:offsets[r + 1] (RelativeState: id, position_m, velocity_mps,
    both assigned). Returns the messages' bytes and offsets (R + 1,)."""
    p = len(neighbour)
    nb = Rows(p).strings(ids, neighbour)
    vector3(nb, 0x12, rel_position_m)
    vector3(nb, 0x1A, rel_velocity_mps)
    entry = Rows(p).nested(0x1A, nb)
    blob, ends = entry.encode()
    off = np.asarray(offsets, dtype=np.int64)
    msg = Rows(headers.n).nested(0x0A, headers).doubles((0x11,), np.full((headers.n, 1), u_rad))
    msg.segments(blob, ends[off[:-1]], ends[off[1:]] - ends[off[:-1]])
    return msg.encode()


def actuator_commands(headers: Rows, accel_mps2: np.ndarray, controllers: tuple[StringTable, np.ndarray],
                      isl_tx_count: np.ndarray, torque_nm: np.ndarray | None) -> tuple[bytes, np.ndarray]:
    """`swarmhil.v1.ActuatorCommand` of R agents (agent/node.py AgentNode.handle): header,
    accel_mps2 (assigned), controller, isl_tx_count, torque_nm (assigned where given: rows of NaN
    in `torque_nm` mean none)."""
    m = Rows(headers.n).nested(0x0A, headers)
    vector3(m, 0x12, accel_mps2)
    m.strings(*controllers).uint(0x20, isl_tx_count)
    if torque_nm is not None:
        has = ~np.isnan(torque_nm).all(axis=1)
        t = Rows(headers.n)
        vector3(t, 0x2A, np.where(has[:, None], torque_nm, 0.0))
        t.parts = [(d, np.where(has, lens, 0)) for d, lens in t.parts]
        m.parts += t.parts
    return m.encode()


def neighbour_decisions(neighbours: StringTable, neighbour: np.ndarray, behaviours: StringTable,
                        behaviour: np.ndarray, d_min_m: np.ndarray, roe_rel_m: np.ndarray,
                        accel_mps2: np.ndarray) -> tuple[bytes, np.ndarray]:
    """Telemetry.decisions entries (field 4) of P decisions, each `NeighbourDecision(neighbour,
    behaviour, d_min_m, roe_rel_m (packed), accel_mps2 (assigned))`: their bytes and offsets."""
    p = len(neighbour)
    d = Rows(p).strings(neighbours, neighbour).strings(behaviours, behaviour).doubles((0x19,), d_min_m[:, None])
    d.packed_doubles(0x22, roe_rel_m)
    vector3(d, 0x2A, accel_mps2)
    return Rows(p).nested(0x22, d).encode()


def telemetry(headers: Rows, modes: tuple[StringTable, np.ndarray], controllers: tuple[StringTable, np.ndarray],
              decisions: tuple[bytes, np.ndarray, np.ndarray], accel_mps2: np.ndarray, compute_s: np.ndarray,
              rejected_packets: np.ndarray) -> tuple[bytes, np.ndarray]:
    """`swarmhil.v1.Telemetry` of R agents without tracks or items (agent/node.py AgentNode.handle):
    header, mode, controller, decisions (`neighbour_decisions`' bytes and ends, and each row's
    decisions offsets (R + 1,) into them), accel_mps2 (assigned), compute_s, rejected_packets."""
    n = headers.n
    m = Rows(n).nested(0x0A, headers).strings(*modes).strings(*controllers)
    blob, ends, off = decisions
    if len(ends) > 1:
        m.segments(blob, ends[off[:-1]], ends[off[1:]] - ends[off[:-1]])
    vector3(m, 0x32, accel_mps2)
    return m.doubles((0x39,), compute_s[:, None]).uint(0x40, rejected_packets).encode()
