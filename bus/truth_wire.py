"""The plant's `swarmhil.v1.Truth` of N spacecraft serialised without building the message (issue 16).

Building a 20-body protobuf `Truth` field by field costs ~50 us a step in Python, more than the
batch mode's physics; its wire bytes are a fixed layout (bus/swarmhil.proto), written here with
numpy, **byte for byte what protobuf's `SerializeToString` gives** for the same values
(tests/test_truth_wire.py, on random and recorded truths): fields in field-number order, proto3
implicit presence (a double is written when its bits are not all zero, so -0.0 and NaN are, +0.0
is not; `false`, 0 and "" are not), a Vector3 that was assigned is present even when empty, and
`roe_m` packed (every element). Only what the plant of the ROE scenarios writes for a spacecraft is
covered: id, position, velocity, delta_v, alive, accel_cmd, kind, roe_m (no attitude, angular
velocity or torque: the truth of a mission world with attitude is still built as a message; its
other bodies, after the spacecraft, are each one serialised message, `encode(..., more_bodies)`).

Wire format (protocol buffers encoding): a field is a tag byte (number << 3 | wire type) then, for
wire type 1 (fixed64) 8 little-endian bytes, for wire type 2 a varint length then the bytes, for
wire type 0 a varint.
"""
from __future__ import annotations

import math
import struct

import numpy as np

_D = struct.Struct("<d")
_SMALL = [bytes((i,)) for i in range(0x80)]


def varint(n: int) -> bytes:
    """Base-128 varint of a non-negative integer (protobuf wire type 0 and lengths)."""
    if n < 0x80:
        return _SMALL[n]
    if n < 0x4000:  # (steps, sequence numbers and lengths of a run: no loop)
        return bytes(((n & 0x7F) | 0x80, n >> 7))
    out = bytearray()
    while n >= 0x80:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


def _string(tag: int, s: str) -> bytes:
    b = s.encode()
    return bytes((tag,)) + varint(len(b)) + b if b else b""


def _double(tag: int, x: float) -> bytes:
    # implicit presence: written unless +0.0 (math.copysign tells -0.0; NaN != 0.0 is written)
    return _SMALL[tag] + _D.pack(x) if (x != 0.0 or math.copysign(1.0, x) < 0.0) else b""  # (tags < 0x80)


def _uint(tag: int, n: int) -> bytes:
    return _SMALL[tag] + varint(n) if n else b""


def encode_header(run: str, source: str, step: int, t: float, seq: int) -> bytes:
    """`swarmhil.v1.Header(run, source, step, t, seq).SerializeToString()`."""
    return _string(0x0A, run) + _string(0x12, source) + _uint(0x18, step) + _double(0x21, t) + _uint(0x28, seq)


class HeaderEncoder:
    """`encode_header` of one publisher (run and source fixed): their bytes made once."""

    def __init__(self, run: str, source: str) -> None:
        self._prefix = _string(0x0A, run) + _string(0x12, source)

    def __call__(self, step: int, t: float, seq: int) -> bytes:
        return self._prefix + _uint(0x18, step) + _double(0x21, t) + _uint(0x28, seq)


def body_entry(body: bytes) -> bytes:
    """One entry of Truth.bodies (field 2) from its serialised BodyState: what the Truth's own
    serialisation writes for it (tag, length, the body's bytes)."""
    return b"\x12" + varint(len(body)) + body


# One body is one row of bytes: every field in field-number order of BodyState, inside Truth
# field 2; a double is a 9-byte slot (tag + 8 bytes), masked out of the row when absent.
_VEC = (0x09, 0x11, 0x19)  # Vector3 x, y, z
_BITS = 1 << np.arange(11, dtype=np.int64)  # a body's 11 present flags -> one integer
MAX_PLANS = 256  # patterns of present fields kept (TruthEncoder._plan; ~30 kB each for 20 bodies)


class TruthEncoder:
    """Serialises the Truth of a fixed list of spacecraft (ids, kind) every step.

    `encode(header, u_rad, a_m, n_radps, position, velocity, delta_v, alive, accel, roe)` returns
    what `pb.Truth(header=..., u_rad=..., semi_major_axis_m=..., mean_motion_radps=...)` with one
    `bodies.add(id, kind, delta_v_mps, alive, roe_m)` per spacecraft and its position_m,
    velocity_mps and accel_cmd_mps2 assigned serialises to. `header` is `encode_header(...)`.

    The fields present (a double that is not +0.0, alive) change rarely from one step to the next:
    the byte layout of each pattern seen is kept (`_plan`), and a step gathers the values' bytes and
    the pattern's fixed bytes in one numpy call.
    """

    def __init__(self, ids: list[str], kinds: list[str] | str = "spacecraft") -> None:
        self.ids = list(ids)
        n = len(self.ids)
        kinds = [kinds] * n if isinstance(kinds, str) else list(kinds)
        id_seg = [_string(0x0A, s) for s in self.ids]
        kind_seg = [_string(0x4A, k) for k in kinds]
        w_id = max((len(s) for s in id_seg), default=0)
        w_kind = max((len(s) for s in kind_seg), default=0)
        cols: list[int] = []  # template bytes of one row (0 where filled per step)
        keep: list[bool] = []
        dbl: list[int] = []  # column of the first value byte of each of the 16 doubles
        opt: list[int] = []  # columns of the 10 optional doubles' 9-byte slots (tag + value)
        sub_len: list[int] = []  # columns of the three Vector3 lengths

        def put(byte: int, kept: bool = True) -> int:
            cols.append(byte)
            keep.append(kept)
            return len(cols) - 1

        def double(tag: int, optional: bool = True) -> None:  # a 9-byte slot, or 8 bytes of a packed field
            if optional:
                opt.extend(range(len(cols), len(cols) + 9))
            if tag:
                put(tag)
            dbl.append(len(cols))
            for _ in range(8):
                put(0)

        def vector3(tag: int) -> None:  # a Vector3 sub-message: tag, length, x, y, z
            put(tag)
            sub_len.append(put(0))
            for t in _VEC:
                double(t)

        put(0x12)  # Truth.bodies (field 2, length-delimited)
        put(0)  # body length, varint low byte
        put(0, False)  # high byte, kept when the length is >= 128
        id_col = len(cols)
        for _ in range(w_id):
            put(0)
        vector3(0x12)  # position_m (2)
        vector3(0x1A)  # velocity_mps (3)
        double(0x21)  # delta_v_mps (4)
        alive_cols = [put(0x28), put(0x01)]  # alive (5)
        vector3(0x42)  # accel_cmd_mps2 (8)
        kind_col = len(cols)
        for _ in range(w_kind):
            put(0)
        put(0x52)  # roe_m (10), packed: 6 doubles, always all written
        put(48)
        for _ in range(6):
            double(0, optional=False)
        width = len(cols)
        tmpl = np.tile(np.array(cols, dtype=np.uint8), (n, 1))
        kmask = np.tile(np.array(keep, dtype=bool), (n, 1))
        for i in range(n):
            for col, seg in ((id_col, id_seg[i]), (kind_col, kind_seg[i])):
                tmpl[i, col:col + len(seg)] = np.frombuffer(seg, dtype=np.uint8)
            kmask[i, id_col:id_col + w_id] = np.arange(w_id) < len(id_seg[i])
            kmask[i, kind_col:kind_col + w_kind] = np.arange(w_kind) < len(kind_seg[i])
        # a plan is made for some rows (the bodies whose pattern is new) through these columns of a row
        self._tmpl, self._keep = tmpl, kmask  # (n, width)
        self._dbl = (np.array(dbl)[:, None] + np.arange(8)).ravel()  # the value bytes of the 16 doubles
        self._slot = np.repeat(np.arange(10), 9)  # the double of each of the 90 optional-slot columns
        self._opt = np.array(opt)
        self._alive = np.array(alive_cols)
        self._sub = np.array(sub_len)
        # (n, 11) presence -> Vector3 lengths (x 9) and the optional bytes of the body
        self._count = np.zeros((11, 4), dtype=np.int64)
        for j, d in enumerate((range(0, 3), range(3, 6), range(7, 10))):
            self._count[list(d), j] = 9
        self._count[:10, 3], self._count[10, 3] = 9, 2
        self._base = kmask[:, 3:].sum(axis=1) - 9 * 10 - 2  # body length without the optional fields
        if width - 3 >= 1 << 14:
            raise ValueError("ids or kinds too long for a two-byte body length")
        self._present = np.empty((n, 16), dtype=bool)  # of each double (the 6 of roe_m are not optional)
        # the values' bytes (n, 16 doubles) followed by the fixed bytes of every pattern seen: a
        # step writes the values in and takes the truth's bytes out in one gather (`_plans` maps
        # a pattern of present fields to its byte indices into this buffer)
        self._nv = n * 16 * 8
        self._buf = np.zeros(self._nv, dtype=np.uint8)
        self._vals = self._buf.view(np.float64).reshape(n, 16)
        self._plans: dict[bytes, np.ndarray] = {}
        self._row_plans: dict[tuple[int, int], np.ndarray] = {}  # (body, its present fields' bits) -> its part of a plan
        self._last: tuple[np.ndarray, list[np.ndarray | None]] | None = None  # the last plan's (patterns as integers, parts)
        self._tail_u: tuple[float, float, bytes] | None = None  # (a, n, their bytes)

    def encode(self, header: bytes, u_rad: float, a_m: float, n_radps: float, position_m: np.ndarray,
               velocity_mps: np.ndarray, delta_v_mps: np.ndarray, alive: np.ndarray, accel_mps2: np.ndarray,
               roe_m: np.ndarray, more_bodies: bytes = b"") -> bytes:
        """The serialised Truth (module docstring); arrays (N, 3), (N, 3), (N,), (N,) bool, (N, 3), (N, 6).
        `more_bodies`: entries of `bodies` after the spacecraft' (`body_entry` of each), as written."""
        v, pr = self._vals, self._present
        n = v.shape[0]
        fixed = self._tail_u
        if fixed is None or fixed[0] != a_m or fixed[1] != n_radps:  # (the same every step of a run)
            fixed = self._tail_u = (a_m, n_radps, _double(0x21, float(a_m)) + _double(0x29, float(n_radps)))
        if n == 0:
            return b"".join((b"\x0a", varint(len(header)), header, more_bodies, _double(0x19, float(u_rad)), fixed[2]))
        np.concatenate((position_m, velocity_mps, delta_v_mps[:, None], accel_mps2, roe_m), axis=1, out=v)
        np.not_equal(v.view(np.uint64), 0, out=pr)  # implicit presence: any bit set (-0.0, NaN); roe_m is packed
        key = pr.tobytes() + np.asarray(alive, dtype=bool).tobytes()
        take = self._plans.get(key)
        if take is None:  # a new pattern of present fields (a 24 h sabatini-20 run has about 120)
            if len(self._plans) >= MAX_PLANS:
                self._plans.clear()
                self._row_plans.clear()
                self._grow(self._buf[:self._nv])
            present = np.empty((n, 11), dtype=bool)
            present[:, :10] = pr[:, :10]
            present[:, 10] = alive
            take = self._plans[key] = self._plan_of_rows(present)
        return b"".join((b"\x0a", varint(len(header)), header, self._buf[take].tobytes(), more_bodies,
                         _double(0x19, float(u_rad)), fixed[2]))

    def _plan_of_rows(self, present: np.ndarray) -> np.ndarray:
        """`_plan` of a pattern (n, 11) from each body's own part (a body's bytes depend on its own
        present fields only: a new pattern is often old rows in a new combination, such as commanded
        components that are exactly zero now and then): `_plan` of the bodies whose pattern has not
        been seen, whose parts are kept per body, the others' parts as kept (in a large swarm some
        body's pattern is new almost every step: only its rows are planned, not all N)."""
        rows = self._row_plans
        codes = present.view(np.uint8) @ _BITS  # each body's pattern as one integer
        last = self._last
        parts: list[np.ndarray | None]
        if last is None or not rows:  # (none yet, or the kept parts were dropped: MAX_PLANS)
            changed, parts = list(range(len(codes))), [None] * len(codes)
        else:  # the bodies whose pattern differs from the last plan's
            changed, parts = np.flatnonzero(codes != last[0]).tolist(), list(last[1])
        keys = {i: (i, c) for i, c in zip(changed, codes[changed].tolist())}
        new = []
        for i, k in keys.items():
            parts[i] = rows.get(k)
            if parts[i] is None:
                new.append(i)
        if new:
            at = np.array(new, dtype=np.intp)
            take, ends = self._plan(present[at], at)
            starts = [0, *ends[:-1].tolist()]
            for i, a, b in zip(new, starts, ends.tolist()):
                parts[i] = rows[keys[i]] = take[a:b]
        self._last = (codes, parts)
        return np.concatenate(parts)  # type: ignore[arg-type]

    def _grow(self, buf: np.ndarray) -> None:
        """Replace the buffer (the values' bytes kept at its start) and the values' view of it."""
        self._buf = buf
        self._vals = buf[:self._nv].view(np.float64).reshape(self._vals.shape)

    def _plan(self, pr: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """For the pattern of present fields pr (m, 11) of the bodies `rows` (default: all, in order):
        the indices into `_buf` of their body bytes (the values' bytes where a present double goes,
        else the pattern's own fixed bytes, appended to `_buf` here), and where each body's bytes
        end among them (m,)."""
        rows = np.arange(len(pr)) if rows is None else np.asarray(rows, dtype=np.intp)
        m, width = len(rows), self._tmpl.shape[1]
        buf = self._tmpl[rows]  # (m, width) copies
        keep = self._keep[rows]
        keep[:, self._opt] = pr[:, self._slot]
        keep[:, self._alive] = pr[:, 10:11]
        lens = pr.view(np.uint8) @ self._count  # (m, 4): position, velocity, accel_cmd lengths; optional bytes
        buf[:, self._sub] = lens[:, :3]
        body = self._base[rows] + lens[:, 3]  # the body's length, a one- or two-byte varint
        long = body >= 0x80
        buf[:, 1] = (body & 0x7F) | (long << 7)
        buf[:, 2] = body >> 7
        keep[:, 2] = long
        flat = keep.ravel()
        at = np.cumsum(flat) - 1  # where each kept byte of the rows lands in the output
        dbl = (np.arange(m)[:, None] * width + self._dbl).ravel()  # (row, double, byte) order
        kept = flat[dbl]
        fixed = buf.ravel()[flat]
        take = len(self._buf) + np.arange(len(fixed), dtype=np.intp)  # the fixed bytes, appended below
        src = (rows[:, None] * len(self._dbl) + np.arange(len(self._dbl))).ravel()  # the values' bytes of these rows
        take[at[dbl][kept]] = src[kept]
        self._grow(np.concatenate((self._buf, fixed)))
        return take, np.cumsum(keep.sum(axis=1))


class TickEncoder:
    """The plant's `swarmhil.v1.Tick` (header, step_s, u_rad, alive, final) serialised without
    building the message: `encode(...)` is `pb.Tick(header=Header(run, "plant", step, t, seq),
    step_s=..., u_rad=..., alive=[the ids whose flag is set], final=...).SerializeToString()`
    (tests/test_truth_wire.py); the alive field's bytes are kept while the flags stay the same."""

    def __init__(self, run: str, ids: list[str], source: str = "plant") -> None:
        self._header = HeaderEncoder(run, source)
        self.ids = list(ids)
        self._alive: tuple[bytes, bytes] = (b"", b"")  # (flags, their field's bytes)

    def encode(self, step: int, t: float, seq: int, step_s: float, u_rad: float, alive: np.ndarray, final: bool) -> bytes:
        flags = np.asarray(alive, dtype=bool).tobytes()
        if flags != self._alive[0]:
            self._alive = (flags, b"".join(_string(0x22, s) if s else b"\x22\x00"
                                           for s, a in zip(self.ids, flags) if a))
        h = self._header(step, t, seq)
        return b"".join((b"\x0a", varint(len(h)), h, _double(0x11, step_s), _double(0x19, u_rad), self._alive[1],
                         b"\x28\x01" if final else b""))
