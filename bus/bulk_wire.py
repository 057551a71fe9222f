"""Protobuf wire bytes of many messages at once from arrays: the batch mode's packets (every agent's
stimulus, command and telemetry of a step) without a protobuf message per packet.

Wire format (protocol buffers encoding): a field is a tag byte (number << 3 | wire type) then,
for wire type 1 (fixed64) 8 little-endian bytes, for wire type 2 a varint length then the
bytes, for wire type 0 a varint; packed repeated doubles are tag, varint 8 n, the n doubles;
fields in field-number order; proto3 implicit presence: a double whose 64 bits are all zero
(+0.0), an integer 0 and an empty string are not written (-0.0 and NaN are), a sub-message that
was assigned is (even when empty). The bytes equal protobuf's `SerializeToString` of the same
values (tests/test_bulk_wire.py checks them against the protobuf library on random values with
+0.0, -0.0, NaN and inf, empty lists and long strings).

How. The bytes of a step's messages of one type are a gather from an *area* (the step's values:
its doubles' 8 bytes each, its varints' bytes) and a *pool* (bytes the layout fixes: tags,
lengths, strings, constant fields): a *plan* says which byte of which goes where. The plan
depends only on the layout (how many messages and sub-messages, which strings, which doubles are
+0.0, how long each varint is), and the layout of a swarm's messages changes seldom from one step
to the next, so each encoder keeps the plans of the layouts it has seen (`MAX_PLANS`): a step whose
layout is known is one gather. A new layout's plan is built by `Rows`: the fields of n messages
of one layout in field order, each field a *part* of at most `w` byte ids per row of which row i
keeps `lens[i]` (all `w` when `lens` is None); nested messages are the sub-rows' parts behind a
head (tag, varint length); repeated sub-messages of variable count per row (a stimulus's
neighbours, a telemetry's decisions) are planned as rows of their own first and enter each message
as one `segments` part.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from swarmhil.bus.truth_wire import varint

MAX_PLANS = 1024  # layouts an encoder keeps (the oldest half is dropped beyond)


def varint_bytes(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Base-128 varints of non-negative integers (n,): bytes (n, w) (w the longest one's length)
    and each one's length (>= 1)."""
    v = np.asarray(values, dtype=np.uint64)
    top = int(v.max()) if len(v) else 0
    if top < 0x80:  # (lengths, sequence numbers and steps of a run: one or two bytes, no loop)
        return v.astype(np.uint8)[:, None], np.ones(len(v), dtype=np.int64)
    if top < 0x4000:
        out = np.empty((len(v), 2), dtype=np.uint8)
        long = v >= 0x80
        out[:, 0] = (v & np.uint64(0x7F)) | (long.astype(np.uint64) << np.uint64(7))
        out[:, 1] = v >> np.uint64(7)
        return out, long + 1
    w = (top.bit_length() + 6) // 7
    shifts = (7 * np.arange(w)).astype(np.uint64)
    groups = (v[:, None] >> shifts[None, :]) & np.uint64(0x7F)  # 7-bit groups, least significant first
    nz = groups != 0  # length: 1 + the index of the highest non-zero group (a zero is one byte)
    lens = np.where(nz.any(axis=1), w - np.argmax(nz[:, ::-1], axis=1), 1)
    more = np.arange(w)[None, :] < (lens[:, None] - 1)  # continuation bit on all but the last
    return groups.astype(np.uint8) | (more.astype(np.uint8) << 7), lens


class Pool:
    """Bytes the layouts fix, shared by the plans: ids -1 - offset (negative; the area's are >= 0)."""

    def __init__(self) -> None:
        self._buf = np.zeros(4096, dtype=np.uint8)  # grown by doubling: array() is a view
        self._n = 0
        self._ids: dict[bytes, np.ndarray] = {}

    def ids(self, b: bytes, shape: tuple[int, ...] | None = None) -> np.ndarray:
        """The ids of bytes `b` (interned: the same bytes, the same ids), shaped `shape`."""
        got = self._ids.get(b)
        if got is None:
            n, k = self._n, len(b)
            if n + k > len(self._buf):
                buf = np.zeros(max(2 * len(self._buf), n + k), dtype=np.uint8)
                buf[:n] = self._buf[:n]
                self._buf = buf
            self._buf[n:n + k] = np.frombuffer(b, dtype=np.uint8)
            self._n = n + k
            got = self._ids[b] = -1 - (n + np.arange(k, dtype=np.int64))
        return got if shape is None else got.reshape(shape)

    def block(self, data: np.ndarray) -> np.ndarray:
        """The ids of a uint8 array's bytes, in its shape."""
        return self.ids(np.ascontiguousarray(data, dtype=np.uint8).tobytes(), data.shape)

    def array(self) -> np.ndarray:
        return self._buf[:self._n]


class StringTable:
    """Length-delimited fields of fixed strings (tag, varint length, UTF-8), one row per string; an
    empty string is a field of length 0 (implicit presence)."""

    def __init__(self, tag: int, strings: Sequence[str]) -> None:
        self.tag = tag
        self.strings = list(strings)
        enc = [bytes((tag,)) + varint(len(b)) + b if b else b"" for b in (s.encode() for s in self.strings)]
        self.width = max([len(e) for e in enc] + [1])
        self.bytes = np.zeros((len(enc), self.width), dtype=np.uint8)
        for i, e in enumerate(enc):
            self.bytes[i, :len(e)] = np.frombuffer(e, dtype=np.uint8)
        self.lens = np.array([len(e) for e in enc], dtype=np.int64)
        self.uniform = bool(len(enc)) and bool((self.lens == self.width).all())  # every field of the table's width
        self.index = {s: i for i, s in enumerate(self.strings)}
        self._seen: dict[tuple[str, ...], np.ndarray] = {}  # lists of strings asked for -> their rows (they recur)

    def indices(self, strings: Sequence[str]) -> np.ndarray:
        """Each string's row, growing the table with the new ones."""
        key = tuple(strings)
        got = self._seen.get(key)
        if got is not None:
            return got
        idx = self.index
        try:
            got = np.array([idx[s] for s in strings], dtype=np.int64)
            got.setflags(write=False)  # (shared by the calls that ask for the same strings)
            if len(self._seen) >= 4096:
                self._seen.clear()
            self._seen[key] = got
            return got
        except KeyError:
            self.__init__(self.tag, self.strings + [s for s in dict.fromkeys(strings) if s not in idx])  # type: ignore[misc]
            return self.indices(strings)


class Rows:
    """The plan of n messages of one layout, field by field (module docstring): parts of byte ids."""

    def __init__(self, n: int, pool: Pool) -> None:
        self.n = n
        self.pool = pool
        self._parts: list[tuple[np.ndarray | _Segments, np.ndarray | None]] = []  # (n, w) ids, (n,) kept lengths or None: w
        self._const = b""  # bytes of every row after the parts (until the next part)

    def _flush(self) -> None:
        if self._const:
            b, self._const = self._const, b""
            self._parts.append((np.broadcast_to(self.pool.ids(b), (self.n, len(b))), None))

    def raw(self, ids: np.ndarray, lens: np.ndarray | None = None) -> "Rows":
        """Row i keeps ids[i, :lens[i]] (None: all of them)."""
        self._flush()
        self._parts.append((ids, None if lens is None else np.asarray(lens, dtype=np.int64)))
        return self

    def const(self, b: bytes) -> "Rows":
        """The same bytes in every row."""
        self._const += b
        return self

    def _tagged(self, tag: int, ids: np.ndarray) -> np.ndarray:
        out = np.empty((self.n, 1 + ids.shape[1]), dtype=np.int64)
        out[:, 0] = self.pool.ids(bytes((tag,)))[0]
        out[:, 1:] = ids
        return out

    def doubles(self, tags: Sequence[int], present: np.ndarray, ids: np.ndarray) -> "Rows":
        """Double fields with tags `tags`: present (n, k) (bits not all zero), value byte ids (n, k, 8)."""
        k = len(tags)
        data = np.empty((self.n, k, 9), dtype=np.int64)
        data[:, :, 0] = self.pool.ids(bytes(tags))
        data[:, :, 1:] = ids
        if present.all():
            return self.raw(data.reshape(self.n, 9 * k))
        self._flush()
        lens = present.astype(np.int64) * 9
        for i in range(k):
            self._parts.append((data[:, i, :], lens[:, i]))
        return self

    def packed(self, tag: int, ids: np.ndarray) -> "Rows":
        """A packed repeated field of the same byte count w > 0 in every row: value byte ids (n, w)."""
        return self.const(bytes((tag,)) + varint(ids.shape[1])).raw(ids)

    def varints(self, tag: int, ids: np.ndarray, lens: np.ndarray, present: np.ndarray) -> "Rows":
        """A varint field (wire type 0): bytes ids (n, w) of lengths `lens`, written where `present`."""
        if not present.any():
            return self
        if present.all() and (lens == ids.shape[1]).all():
            return self.raw(self._tagged(tag, ids))
        return self.raw(self._tagged(tag, ids), np.where(present, lens + 1, 0))

    def strings(self, table: StringTable, idx: np.ndarray) -> "Rows":
        """Row i's string field is table row idx[i]."""
        idx = np.broadcast_to(np.asarray(idx, dtype=np.int64), (self.n,))
        return self.raw(self.pool.block(table.bytes)[idx], None if table.uniform else table.lens[idx])

    def length(self) -> "int | np.ndarray":
        """The rows' encoded length: an int when every row has the same, else (n,)."""
        fixed = len(self._const)
        var = None
        for d, lens in self._parts:
            if lens is None:
                fixed += d.shape[1]
            else:
                var = lens.copy() if var is None else var + lens
        return fixed if var is None else var + fixed

    def head(self, tag: int, lengths: "int | np.ndarray") -> "Rows":
        """The head of a length-delimited field: tag, varint length."""
        if isinstance(lengths, int):
            return self.const(bytes((tag,)) + varint(lengths))
        v, lens = varint_bytes(lengths)
        return self.raw(self._tagged(tag, self.pool.block(v)), lens + 1)

    def nested(self, tag: int, sub: "Rows") -> "Rows":
        """A sub-message field (present even when empty) whose fields are `sub`'s."""
        self.head(tag, sub.length())
        if sub._parts:
            self._flush()
            self._parts.extend(sub._parts)
        self._const += sub._const
        return self

    def segments(self, ids: np.ndarray, ends: np.ndarray, offsets: np.ndarray) -> "Rows":
        """Row i gets rows offsets[i]:offsets[i + 1] of a plan (ids, ends) of sub-rows (repeated fields)."""
        if self.n == 0 or len(ids) == 0:
            return self
        off = np.asarray(offsets, dtype=np.int64)
        a = ends[off[:-1]]
        self._flush()
        self._parts.append((_Segments(ids, a), ends[off[1:]] - a))
        return self

    def plan(self) -> tuple[np.ndarray, np.ndarray]:
        """The ids of every row's bytes, concatenated in row order, and the row offsets (n + 1,)."""
        self._flush()
        parts = [(d, lens) for d, lens in self._parts if d.shape[1]]
        n = self.n
        if not parts or n == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(n + 1, dtype=np.int64)
        if all(lens is None for _, lens in parts):  # every byte of every part: one concatenation
            data = np.concatenate([d for d, _ in parts], axis=1)
            return data.ravel(), np.arange(n + 1, dtype=np.int64) * data.shape[1]
        sources, starts, sizes = [], [], []  # one gather: each row's piece of each part is a range of the sources
        at = 0
        for d, ln in parts:
            if isinstance(d, _Segments):
                sources.append(d.ids)
                starts.append(d.starts + at)
                at += len(d.ids)
            else:
                w = d.shape[1]
                sources.append(d.reshape(-1))
                starts.append(np.arange(at, at + n * w, w))
                at += n * w
            sizes.append(np.full(n, d.shape[1]) if ln is None else ln)
        start = np.stack(starts, axis=1).ravel()
        size = np.stack(sizes, axis=1)
        ends = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(size.sum(axis=1), out=ends[1:])
        size = size.ravel()
        before = np.cumsum(size) - size  # where each piece lands
        return np.concatenate(sources)[np.repeat(start - before, size) + np.arange(int(ends[-1]))], ends


class _Segments:
    """A `Rows.segments` part: ranges of a plan's ids (shape[1] 1 only says it is not empty)."""

    shape = (0, 1)

    def __init__(self, ids: np.ndarray, starts: np.ndarray) -> None:
        self.ids, self.starts = ids, starts


class Area:
    """One step's values, the bytes its plans gather with the pool's: doubles (8 bytes each, ids
    8 k ... 8 k + 7 in the order added), then varints."""

    def __init__(self, doubles: np.ndarray) -> None:
        self.doubles = np.ascontiguousarray(doubles, dtype=np.float64).ravel()
        self.present = self.doubles.view(np.uint64) != 0  # implicit presence of each double
        self._ints: list[np.ndarray] = []
        self._n_ints = 0
        self.key: list[bytes] = [self.present.tobytes()]  # what the values fix of the layout

    def double_ids(self, start: int, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """(present, byte ids (*shape, 8)) of the doubles start ... start + prod(shape) - 1."""
        k = int(np.prod(shape))
        return (self.present[start:start + k].reshape(shape),
                (8 * start + np.arange(8 * k, dtype=np.int64)).reshape(*shape, 8))

    def varint(self, value: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`varints` of one value."""
        b = varint(value)
        base = 8 * len(self.doubles) + self._n_ints
        self._ints.append(np.frombuffer(b, dtype=np.uint8))
        self._n_ints += len(b)
        k = (1, base, len(b), value != 0)
        self.key.append(_ONE_KEY[k[2:]])
        got = _SAME.get(k)
        if got is None:
            if len(_SAME) > 4096:
                _SAME.clear()
            got = _SAME[k] = (base + np.arange(len(b), dtype=np.int64)[None, :], np.full(1, len(b), dtype=np.int64),
                              np.full(1, value != 0))
        return got

    def varints(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Varints of (n,) integers added: (byte ids (n, w), lengths, present (value != 0)). One
        value for all (a swarm whose spacecraft are all alive: their sequence numbers) is added once."""
        v = np.asarray(values, dtype=np.uint64)
        n = len(v)
        lo = int(v.min()) if n else 0
        base = 8 * len(self.doubles) + self._n_ints
        if n and (n == 1 or lo == int(v.max())):
            b = varint(lo)
            self._ints.append(np.frombuffer(b, dtype=np.uint8))
            self._n_ints += len(b)
            k = (n, base, len(b), lo != 0)
            self.key.append(_ONE_KEY[k[2:]])
            got = _SAME.get(k)
            if got is None:
                if len(_SAME) > 4096:
                    _SAME.clear()
                got = _SAME[k] = (np.broadcast_to(base + np.arange(len(b), dtype=np.int64), (n, len(b))),
                                  np.full(n, len(b), dtype=np.int64), np.full(n, lo != 0))
            return got
        data, lens = varint_bytes(v)
        self._ints.append(data.ravel())
        self._n_ints += data.size
        present = v != 0
        self.key += [lens.tobytes(), present.tobytes()]
        return base + np.arange(data.size, dtype=np.int64).reshape(data.shape), lens, present

    def raw(self, data: bytes) -> int:
        """Bytes added as they are (a `bytes` field's content): the id of the first. Their length is
        the caller's to put in the layout key."""
        base = 8 * len(self.doubles) + self._n_ints
        self._ints.append(np.frombuffer(data, dtype=np.uint8))
        self._n_ints += len(data)
        return base

    def chunks(self) -> list[np.ndarray]:
        """The area's bytes in pieces (the doubles', then each varint array's)."""
        return [self.doubles.view(np.uint8), *self._ints]

    def bytes(self) -> np.ndarray:
        return np.concatenate(self.chunks())


class Gather:
    """A plan made ready to gather: the bytes it takes from the pool (a template) and, for each
    byte of the output, where it comes from in the step's area followed by the template (one gather)."""

    def __init__(self, ids: np.ndarray, pool: Pool, area_size: int) -> None:
        neg = ids < 0
        self.template = pool.array()[-1 - ids[neg]]
        self.idx = ids.copy()
        self.idx[neg] = area_size + np.arange(int(neg.sum()))
        self.area_size = area_size

    def __call__(self, area: np.ndarray) -> bytes:
        return np.concatenate((area, self.template))[self.idx].tobytes()


_SAME: dict[tuple[int, int, int, bool], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # Area.varints of one value for all
_ONE_KEY = {(n, z): b"=%d%s" % (n, b"+" if z else b"0") for n in range(1, 11) for z in (False, True)}


class Plans:
    """The plans of one encoder by layout key (the newest MAX_PLANS): ids and message offsets."""

    def __init__(self, pool: Pool) -> None:
        self.pool = pool
        self._plans: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray]] = {}
        self._gathers: dict[tuple[Any, ...], Gather] = {}
        self.built = 0  # plans built (the other steps reused one)

    def plan(self, key: tuple[Any, ...], build: "Callable[[], tuple[np.ndarray, np.ndarray]]") -> tuple[np.ndarray, np.ndarray]:
        got = self._plans.get(key)
        if got is None:
            if len(self._plans) >= MAX_PLANS:
                for k in list(self._plans)[:MAX_PLANS // 2]:
                    del self._plans[k]
                    self._gathers.pop(k, None)
            got = self._plans[key] = build()
            self.built += 1
        return got

    def gather(self, key: tuple[Any, ...], build: "Callable[[], tuple[np.ndarray, np.ndarray]]",
               area_size: int) -> tuple[Gather, np.ndarray]:
        ids, ends = self.plan(key, build)
        g = self._gathers.get(key)
        if g is None:
            g = self._gathers[key] = Gather(ids, self.pool, area_size)
        return g, ends


@dataclass
class Prepared:
    """One encoder's messages of a step, ready to be gathered: their layout key, the step's values
    and how to plan a new layout."""

    key: tuple[Any, ...]
    area: Area
    plans: Plans
    build: "Callable[[], tuple[np.ndarray, np.ndarray]]"

    def encode(self) -> tuple[bytes, np.ndarray]:
        """The messages' bytes, concatenated, and their offsets."""
        area = self.area.bytes()
        g, ends = self.plans.gather(self.key, self.build, len(area))
        return g(area), ends

    def plan(self) -> tuple[np.ndarray, np.ndarray]:
        return self.plans.plan(self.key, self.build)


def ranges(starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """The indices start_i ... start_i + size_i - 1 of every range i, end to end."""
    before = np.cumsum(sizes) - sizes
    return np.repeat(np.asarray(starts, dtype=np.int64) - before, sizes) + np.arange(int(before[-1] + sizes[-1]) if len(sizes) else 0)


_VEC3 = (0x09, 0x11, 0x19)  # Vector3 x, y, z


def _vector3(rows: Rows, tag: int, present: np.ndarray, ids: np.ndarray) -> Rows:
    """A Vector3 field that was assigned (present even when empty): x, y, z present (n, 3), ids (n, 3, 8)."""
    return rows.nested(tag, Rows(rows.n, rows.pool).doubles(_VEC3, present, ids))


def _header(n: int, pool: Pool, area: Area, prefix: bytes, sources: "tuple[StringTable, np.ndarray] | None",
            step: tuple[np.ndarray, np.ndarray, np.ndarray], t_at: int, seq: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Rows:
    """n `swarmhil.v1.Header`s: `prefix` the run (and source, when it is one for all) fields, `sources`
    (table, row) each row's source otherwise; step (one varint), t (the double at t_at), seq (n varints)."""
    h = Rows(n, pool).const(prefix)
    if sources is not None:
        h.strings(*sources)
    s_ids, s_lens, s_present = step
    h.varints(0x18, np.broadcast_to(s_ids, (n, s_ids.shape[1])), np.broadcast_to(s_lens, (n,)),
              np.broadcast_to(s_present, (n,)))
    present, ids = area.double_ids(t_at, (1, 1))
    h.doubles((0x21,), np.broadcast_to(present, (n, 1)), np.broadcast_to(ids, (n, 1, 8)))
    return h.varints(0x28, *seq)


def _string(tag: int, s: str) -> bytes:
    b = s.encode()
    return bytes((tag,)) + varint(len(b)) + b if b else b""


class RelStimuli:
    """`swarmhil.v1.RelStimulus` of the observers of a step (plant/sensing/builtin.py RelKind.stimuli):
    header (source `source`), u_rad, neighbours (RelativeState: id, position_m, velocity_mps, both
    assigned); or `swarmhil.v1.Measurements`, the same fields then `items` (bus/codec.py
    `add_measurement`: name, subject, values, shape): either named flat arrays of the
    same length for every observer, without a subject (the `relative` kind's own state), or each
    observer's own named arrays, keyed `name/subject` as a mission kind's batch form gives them
    (plant/sensing/builtin.py RelBatch.named: papers 003 and 004)."""

    def __init__(self, pool: Pool, run: str, source: str, ids: Sequence[str]) -> None:
        self.pool, self.plans = pool, Plans(pool)
        self.prefix = _string(0x0A, run) + _string(0x12, source)
        self.ids = StringTable(0x0A, ids)
        self._own: dict[tuple, tuple[tuple[tuple[str, str, int, tuple[int, ...]], ...], np.ndarray]] = {}  # `_own_items`

    def prepare(self, step: int, t: float, seq: np.ndarray, u_rad: float, offsets: np.ndarray, neighbour: np.ndarray,
                rel_position_m: np.ndarray, rel_velocity_mps: np.ndarray,
                items: "dict[str, np.ndarray] | Sequence[dict[str, np.ndarray]] | None" = None) -> "Prepared | Appended":
        """The stimuli of R observers: observer r's neighbours are rows offsets[r]:offsets[r + 1] of
        `neighbour` (indices into the ids) and the (P, 3) relative states; `items` (Measurements):
        name -> (R, k) values, observer r's row r; or R dicts `name/subject` -> values of any shape,
        observer r's the r-th (a key without "/": no subject)."""
        off = np.asarray(offsets, dtype=np.int64)
        nb = np.asarray(neighbour, dtype=np.int64)
        r, p = len(off) - 1, len(nb)
        own: "tuple[tuple[str, str, int, tuple[int, ...]], ...]" = ()  # each observer's items (name, subject, size, shape)
        own_off = _NO_OFFSETS
        own_values: list[np.ndarray] = []
        own_key: tuple = ()
        if items is not None and not isinstance(items, dict) and any(
                np.ndim(v) != 1 for named_i in items for v in named_i.values()):
            # arrays of rows (paper 000's visible landmarks, (K, 3)): their count changes from step to step, so
            # a plan would rarely be seen twice; each observer's items are written as they are after its message
            tails = [b"".join([_item_field(k, v) for k, v in named_i.items()]) for named_i in items]
            base = self.prepare(step, t, seq, u_rad, offsets, neighbour, rel_position_m, rel_velocity_mps)
            assert isinstance(base, Prepared)  # (without items)
            return Appended(base, tails)
        if items is not None and not isinstance(items, dict):
            layout, own_values = [], []
            for named_i in items:  # (the keys and shapes: the layout, parsed once per layout)
                layout.append(tuple([(k, np.shape(v)) for k, v in named_i.items()]))
                own_values += named_i.values()
            own_key = tuple(layout)
            got = self._own.get(own_key)
            if got is None:
                if len(self._own) >= MAX_PLANS:
                    self._own.clear()
                got = self._own[own_key] = _own_items(own_key)
            own, own_off = got
            items = None
        named = [(name, np.asarray(v, dtype=float).reshape(r, -1)) for name, v in (items or {}).items()]
        n_own = sum([o[2] for o in own])
        d = np.empty(2 + 6 * p + sum(v.size for _n, v in named) + n_own)
        d[0], d[1] = t, u_rad
        d[2:2 + 6 * p].reshape(p, 6)[:, :3] = rel_position_m
        d[2:2 + 6 * p].reshape(p, 6)[:, 3:] = rel_velocity_mps
        at = 2 + 6 * p
        for _n, v in named:
            d[at:at + v.size] = v.ravel()
            at += v.size
        if n_own:
            d[at:] = np.concatenate([np.ravel(v) for v in own_values])
        area = Area(d)
        step_v, seq_v = area.varint(step), area.varints(seq)
        key = (off.tobytes(), nb.tobytes(), *area.key, *(f"{n}:{v.shape[1]}".encode() for n, v in named), own_key)

        def build() -> tuple[np.ndarray, np.ndarray]:
            pool = self.pool
            present, ids = area.double_ids(2, (p, 6))
            e = Rows(p, pool).strings(self.ids, nb)
            _vector3(e, 0x12, present[:, :3], ids[:, :3])
            _vector3(e, 0x1A, present[:, 3:], ids[:, 3:])
            entries = Rows(p, pool).nested(0x1A, e).plan()
            m = Rows(r, pool).nested(0x0A, _header(r, pool, area, self.prefix, None, step_v, 0, seq_v))
            present, ids = area.double_ids(1, (1, 1))
            m.doubles((0x11,), np.broadcast_to(present, (r, 1)), np.broadcast_to(ids, (r, 1, 8)))
            m.segments(*entries, off)
            at = 2 + 6 * p
            for name, v in named:  # Measurements.items (field 4): Measurement(name, values packed)
                k = v.shape[1]
                item = Rows(r, pool).const(_string(0x0A, name))
                if k:
                    item.packed(0x1A, area.double_ids(at, (r, k))[1].reshape(r, 8 * k))
                m.nested(0x22, item)
                at += r * k
            if own:  # each observer's own items: one sub-row each, of its own length, then segments
                parts, ends = [], [0]
                for name, subject, size, shape in own:
                    item = Rows(1, pool).const(_string(0x0A, name) + _string(0x12, subject))
                    if size:
                        item.packed(0x1A, area.double_ids(at, (1, size))[1].reshape(1, 8 * size))
                    if shape:  # Measurement.shape (packed uint32) of an array that is not flat
                        dims = b"".join(varint(int(x)) for x in shape)
                        item.const(bytes((0x22,)) + varint(len(dims)) + dims)
                    ids_, _e = Rows(1, pool).nested(0x22, item).plan()
                    parts.append(ids_)
                    ends.append(ends[-1] + len(ids_))
                    at += size
                m.segments(np.concatenate(parts), np.array(ends, dtype=np.int64), own_off)
            return m.plan()

        return Prepared(key, area, self.plans, build)

    def encode(self, *args: Any) -> tuple[bytes, np.ndarray]:
        """`prepare` of the same arguments, encoded."""
        return self.prepare(*args).encode()


_NO_OFFSETS = np.zeros(1, dtype=np.int64)


class Appended:
    """Messages of an encoder (`base`) each followed by bytes of its own (`tails`: fields that
    come last in the message, protobuf's field order): `encode` as Prepared's."""

    def __init__(self, base: Prepared, tails: list[bytes]) -> None:
        self.base, self.tails = base, tails

    def encode(self) -> tuple[bytes, np.ndarray]:
        blob, ends = self.base.encode()
        e = ends.tolist()
        out = b"".join([blob[a:b] + tail for a, b, tail in zip(e[:-1], e[1:], self.tails)])
        sizes = np.diff(ends) + np.fromiter(map(len, self.tails), dtype=np.int64, count=len(self.tails))
        new = np.zeros(len(ends), dtype=np.int64)
        np.cumsum(sizes, out=new[1:])
        return out, new


def _item_field(key: str, v: Any) -> bytes:
    """Measurements.items (field 4) of one named array, keyed `name/subject` (or `name`): bus/codec.py
    `add_measurement`'s Measurement (name, subject, values packed float64, shape packed unless flat)."""
    a = np.asarray(v, dtype=float)
    name, _, subject = key.rpartition("/") if "/" in key else (key, "", "")
    body = _string(0x0A, name) + _string(0x12, subject)
    if a.size:
        body += b"\x1a" + varint(8 * a.size) + a.astype("<f8").tobytes()
    if a.ndim > 1:  # (a flat or 0-d array: no shape)
        dims = b"".join(varint(int(x)) for x in a.shape)
        body += b"\x22" + varint(len(dims)) + dims
    return b"\x22" + varint(len(body)) + body


def _own_items(layout: tuple) -> tuple[tuple[tuple[str, str, int, tuple[int, ...]], ...], np.ndarray]:
    """Each observer's items of a layout (per observer: its (`name/subject` key, shape) pairs):
    (name, subject, size, the shape written: () for a flat array) of each, in order, and the
    observers' offsets into them."""
    own = []
    off = np.zeros(len(layout) + 1, dtype=np.int64)
    for i, pairs in enumerate(layout):
        for key, shape in pairs:
            name, _, subject = key.rpartition("/") if "/" in key else (key, "", "")
            own.append((name, subject, int(np.prod(shape, dtype=np.int64)), tuple(shape) if len(shape) != 1 else ()))
        off[i + 1] = len(own)
    return tuple(own), off


class AgentMessages:
    """Each agent's `swarmhil.v1.ActuatorCommand` and `swarmhil.v1.Telemetry` of a step (agent/node.py
    AgentNode.handle) for commands that are an acceleration, a mode and decisions (no transmission,
    torque, extra arrays or tracks): ActuatorCommand(header, accel_mps2, controller),
    Telemetry(header, mode, controller, decisions, accel_mps2, compute_s, rejected_packets = 0)."""

    def __init__(self, pool: Pool, run: str, ids: Sequence[str], controllers: Sequence[str]) -> None:
        self.pool = pool
        self.act_plans, self.tm_plans = Plans(pool), Plans(pool)
        self.prefix = _string(0x0A, run)
        self.sources = StringTable(0x12, ids)  # Header.source
        self.neighbours = StringTable(0x0A, ids)  # NeighbourDecision.neighbour
        self.controllers = StringTable(0x1A, controllers)  # ActuatorCommand.controller, Telemetry.controller
        self.modes = StringTable(0x12, [])  # Telemetry.mode
        self.behaviours = StringTable(0x12, [])  # NeighbourDecision.behaviour

    def commands(self, step: int, t: float, seq: np.ndarray, rows: np.ndarray, accel_mps2: np.ndarray,
                 isl_tx_count: "np.ndarray | None" = None) -> Prepared:
        """The commands of the agents `rows` (indices into ids); `isl_tx_count`: each one's packets
        of the step (None: none)."""
        r = len(rows)
        d = np.empty(1 + 3 * r)
        d[0] = t
        d[1:].reshape(r, 3)[:] = accel_mps2
        area = Area(d)
        step_v, seq_v = area.varint(step), area.varints(seq)
        tx_v = area.varints(isl_tx_count) if isl_tx_count is not None and len(isl_tx_count) else None
        rows = np.asarray(rows, dtype=np.int64)
        key = (rows.tobytes(), *area.key)

        def build() -> tuple[np.ndarray, np.ndarray]:
            m = Rows(r, self.pool).nested(0x0A, _header(r, self.pool, area, self.prefix, (self.sources, rows), step_v, 0, seq_v))
            _vector3(m, 0x12, *area.double_ids(1, (r, 3)))
            m.strings(self.controllers, rows)
            if tx_v is not None:
                m.varints(0x20, np.broadcast_to(tx_v[0], (r, tx_v[0].shape[1])), np.broadcast_to(tx_v[1], (r,)),
                          np.broadcast_to(tx_v[2], (r,)))
            return m.plan()

        return Prepared(key, area, self.act_plans, build)

    def telemetry(self, step: int, t: float, seq: np.ndarray, rows: np.ndarray, modes: Sequence[str],
                  accel_mps2: np.ndarray, compute_s: float, offsets: np.ndarray, neighbour: "np.ndarray | Sequence[str]",
                  labels: Sequence[str], behaviour: np.ndarray, d_min_m: np.ndarray, roe_rel_m: np.ndarray,
                  decision_accel_mps2: np.ndarray) -> Prepared:
        """The telemetry of the agents `rows`: modes, accelerations (R, 3), each one's share of the
        compute time, and decisions offsets[i]:offsets[i + 1] (neighbour: names, or indices into the
        ids; behaviour: indices into `labels`; d_min, roe (P, 6), acceleration (P, 3))."""
        r, p = len(rows), len(neighbour)
        d = np.empty(2 + 3 * r + 10 * p)
        d[0], d[1] = t, compute_s
        d[2:2 + 3 * r].reshape(r, 3)[:] = accel_mps2
        dec = d[2 + 3 * r:].reshape(p, 10)
        dec[:, 0] = d_min_m
        dec[:, 1:7] = roe_rel_m
        dec[:, 7:] = decision_accel_mps2
        area = Area(d)
        step_v, seq_v = area.varint(step), area.varints(seq)
        rows = np.asarray(rows, dtype=np.int64)
        off = np.asarray(offsets, dtype=np.int64)
        mode = self.modes.indices(modes)
        beh = self.behaviours.indices(labels)[np.asarray(behaviour, dtype=np.int64)] if p else np.zeros(0, dtype=np.int64)
        nb = neighbour if isinstance(neighbour, np.ndarray) else self.neighbours.indices(neighbour)
        key = (rows.tobytes(), off.tobytes(), mode.tobytes(), beh.tobytes(), nb.tobytes(), *area.key)

        def build() -> tuple[np.ndarray, np.ndarray]:
            pool, base = self.pool, 2 + 3 * r
            e = Rows(p, pool).strings(self.neighbours, nb).strings(self.behaviours, beh)
            present, ids = area.double_ids(base, (p, 10))
            e.doubles((0x19,), present[:, :1], ids[:, :1])
            e.packed(0x22, ids[:, 1:7].reshape(p, 48))
            _vector3(e, 0x2A, present[:, 7:], ids[:, 7:])
            entries = Rows(p, pool).nested(0x22, e).plan()
            m = Rows(r, pool).nested(0x0A, _header(r, pool, area, self.prefix, (self.sources, rows), step_v, 0, seq_v))
            m.strings(self.modes, mode).strings(self.controllers, rows).segments(*entries, off)
            _vector3(m, 0x32, *area.double_ids(2, (r, 3)))
            present, ids = area.double_ids(1, (1, 1))
            return m.doubles((0x39,), np.broadcast_to(present, (r, 1)), np.broadcast_to(ids, (r, 1, 8))).plan()

        return Prepared(key, area, self.tm_plans, build)


class IslPackets:
    """`swarmhil.v1.IslPacket`s: header (source per packet, one step and time, seq per packet), src,
    dst, type, payload, sent_t: an agent's transmissions on its isl/tx key (agent/node.py
    `isl_packet`) or the link channel's deliveries on the receivers' isl/rx keys (link/node.py
    `_publish`)."""

    def __init__(self, pool: Pool, run: str) -> None:
        self.pool, self.plans = pool, Plans(pool)
        self.prefix = _string(0x0A, run)
        self.sources = StringTable(0x12, [])  # Header.source
        self.srcs = StringTable(0x12, [])  # src
        self.dsts = StringTable(0x1A, [])  # dst
        self.types = StringTable(0x22, [])  # type

    def prepare(self, step: int, t: float, seq: Sequence[int], sources: Sequence[str], srcs: Sequence[str],
                dsts: Sequence[str], types: Sequence[str], payloads: Sequence[bytes], sent_t: Sequence[float]) -> Prepared:
        """n packets of one step and time (the header's), each with its own seq, source, fields."""
        n = len(payloads)
        d = np.empty(1 + n)
        d[0] = t
        d[1:] = sent_t
        area = Area(d)
        step_v, seq_v = area.varint(step), area.varints(np.asarray(seq, dtype=np.uint64))
        lens = np.fromiter(map(len, payloads), dtype=np.int64, count=n)
        base = area.raw(b"".join(payloads))
        so, sr, ds, ty = (table.indices(v) for table, v in
                          ((self.sources, sources), (self.srcs, srcs), (self.dsts, dsts), (self.types, types)))
        key = (so.tobytes(), sr.tobytes(), ds.tobytes(), ty.tobytes(), lens.tobytes(), *area.key)

        def build() -> tuple[np.ndarray, np.ndarray]:
            pool = self.pool
            m = Rows(n, pool).nested(0x0A, _header(n, pool, area, self.prefix, (self.sources, so), step_v, 0, seq_v))
            m.strings(self.srcs, sr).strings(self.dsts, ds).strings(self.types, ty)
            heads = [pool.ids(bytes((0x2A,)) + varint(k)) if k else np.zeros(0, dtype=np.int64) for k in lens.tolist()]
            kept = np.array([len(h) + k for h, k in zip(heads, lens.tolist())], dtype=np.int64)
            ids = np.zeros((n, int(kept.max()) if n else 0), dtype=np.int64)
            at = base
            for i, (h, k) in enumerate(zip(heads, lens.tolist())):  # payload (field 5): absent when empty
                ids[i, :len(h)] = h
                ids[i, len(h):len(h) + k] = at + np.arange(k)
                at += k
            m.raw(ids, kept)
            present, ids_t = area.double_ids(1, (n, 1))
            return m.doubles((0x31,), present, ids_t).plan()

        return Prepared(key, area, self.plans, build)


def split(blob: bytes, ends: np.ndarray) -> list[bytes]:
    """The messages of an encoder's result as separate bytes."""
    e = ends.tolist()
    return [blob[a:b] for a, b in zip(e[:-1], e[1:])]
