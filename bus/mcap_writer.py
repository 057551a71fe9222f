"""The recorder's MCAP writer: mcap's `Writer` with a cheaper per-message path and a chosen zstd level (issue 16).

A batch run records one truth of ~3.5 kB a step, and mcap-python's `add_message` (a `Message`
dataclass, then seven `struct.pack` and `BytesIO` calls per record) plus zstd at its default
level 3 were a quarter of a drift-20 batch step. This writer produces the same records (the
Message record's bytes are one `struct.pack` of the same fields, the chunk's message index and
the file's statistics are updated as mcap's own code does) and compresses each chunk with zstd at
`ZSTD_LEVEL` (1: on a 24 h drift-20 recording the same size as level 3 within 2 %, 40 % less CPU;
the level is not part of the MCAP contract, the readers decompress any level). With
`background=True` (the in-process runs, deploy/launcher.py) a closed chunk is compressed on a
worker thread (zstd releases the GIL) while the run goes on, and its records are written once
it is compressed (or at the next other write to the stream, waiting for it), before anything added
after it: the records' order in the file is the same. (The recorder process of a multi-process run keeps compressing in place: what a SIGKILL can
lose stays the open chunk.)

It works on the internals of the pinned mcap (`mcap==1.6.0`: `_Writer__statistics`,
`_Writer__chunk_builder`, `_Writer__finalize_chunk`); with another mcap whose internals differ it
falls back to mcap's own `add_message` (and its default level), so it still writes a correct
file. tests/test_mcap_writer.py reads what it writes back with the standard readers.
"""
from __future__ import annotations

import struct
import zlib
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import IO, Any

import numpy as np
import zstandard
from mcap.records import Chunk, ChunkIndex
from mcap.writer import CompressionType, IndexType, Writer

from swarmhil.bus.bulk_wire import MAX_PLANS, Gather, Pool, Prepared, ranges

ZSTD_LEVEL = 1
_MESSAGE = struct.Struct("<BQHIQQ")  # opcode 0x05, record length, channel id, sequence, log time, publish time
_OP_MESSAGE = 0x05
_OP_MESSAGE_INDEX = 0x07
_MESSAGE_FIXED = 2 + 4 + 8 + 8  # the record's bytes before its data
_MESSAGE_DTYPE = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                           ("log_time", "<u8"), ("publish_time", "<u8")])  # _MESSAGE as a packed record


class RecorderWriter(Writer):
    """`mcap.writer.Writer` (chunked, zstd, every index) with the fast paths above."""

    def __init__(self, output: IO[Any], chunk_size: int, zstd_level: int = ZSTD_LEVEL, background: bool = False) -> None:
        self._pending: deque[tuple] = deque()  # closed chunks, in order: (future, start, end, size, message indexes)
        self._bulk: list[tuple[np.ndarray, np.ndarray, "int | np.ndarray"]] = []  # add_messages of the open chunk: (channels, offsets, log time: one or each's)
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="mcap-zstd") if background else None
        super().__init__(output, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._zstd = zstandard.ZstdCompressor(level=zstd_level)
        self._fast_chunk_size = chunk_size
        names = ("_Writer__statistics", "_Writer__chunk_builder", "_Writer__chunk_indices", "_Writer__record_builder",
                 "_Writer__stream", "_Writer__index_types", "_Writer__enable_crcs")
        self._fast = all(hasattr(self, n) for n in names) and hasattr(Writer, "_Writer__finalize_chunk")
        if self._fast:
            self._stats = self._Writer__statistics  # type: ignore[attr-defined]
            self._chunk = self._Writer__chunk_builder  # type: ignore[attr-defined]

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        """`Writer.add_message`, the same bytes and bookkeeping, without building a `Message`."""
        if not self._fast:
            return super().add_message(channel_id, log_time, data, publish_time, sequence)
        st = self._stats
        if st.message_count == 0 or log_time < st.message_start_time:
            st.message_start_time = log_time
        if log_time > st.message_end_time:
            st.message_end_time = log_time
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        cb = self._chunk  # mcap's ChunkBuilder.add_message, then Message.write
        if cb.num_messages == 0 or log_time < cb.message_start_time:
            cb.message_start_time = log_time
        if log_time > cb.message_end_time:
            cb.message_end_time = log_time
        buf = cb.record_writer._buffer  # (a new BytesIO after each chunk)
        index = cb.message_indices.get(channel_id)  # here: the flat (log time, offset) list of the channel
        if index is None:
            index = cb.message_indices[channel_id] = []
        elif isinstance(index, np.ndarray):  # (a channel `_fold` filled: entries of the bulk paths)
            index = cb.message_indices[channel_id] = index.tolist()
        index += (log_time, buf.tell())
        cb.num_messages += 1
        buf.write(_MESSAGE.pack(_OP_MESSAGE, _MESSAGE_FIXED + len(data), channel_id, sequence, log_time, publish_time))
        buf.write(data)
        if buf.tell() > self._fast_chunk_size:
            self._Writer__finalize_chunk()

    def add_messages(self, channel_ids: list[int], log_time: "int | np.ndarray", blob: bytes, starts: np.ndarray,
                     sizes: np.ndarray, publish_time: int, sequence: int) -> None:
        """`add_message` of n messages at once: message i is blob[starts[i]:starts[i] + sizes[i]] on
        channel_ids[i], with sequence `sequence + i`, at `log_time` (one for all, or each one's (n,)).
        The same records; they go to the chunk as one buffer (the chunk is closed after them, not
        between), and their message index entries and channel counts are added when the chunk is
        closed (`_fold`)."""
        n = len(channel_ids)
        if not self._fast:
            times = np.broadcast_to(np.asarray(log_time, dtype=np.int64), (n,)).tolist()
            for i, (a, m) in enumerate(zip(np.asarray(starts).tolist(), np.asarray(sizes).tolist())):
                self.add_message(channel_ids[i], times[i], blob[a:a + m], publish_time, sequence + i)
            return
        if n == 0:
            return
        if isinstance(log_time, np.ndarray):
            buf = self._count(n, int(log_time.min()), int(log_time.max()))
        else:
            buf = self._count(n, log_time)
        size = np.asarray(sizes, dtype=np.int64)
        head = np.empty(n, dtype=_MESSAGE_DTYPE)
        head["op"] = _OP_MESSAGE
        head["length"] = _MESSAGE_FIXED + size
        head["channel"] = channel_ids
        head["sequence"] = np.arange(sequence, sequence + n)
        head["log_time"] = log_time
        head["publish_time"] = publish_time
        # the records: each one's 31-byte head, then its data, gathered from the heads and the blob
        hs = _MESSAGE.size
        piece_start = np.empty((n, 2), dtype=np.int64)
        piece_start[:, 0] = np.arange(0, n * hs, hs)
        piece_start[:, 1] = np.asarray(starts, dtype=np.int64) + n * hs
        pieces = np.empty((n, 2), dtype=np.int64)
        pieces[:, 0] = hs
        pieces[:, 1] = size
        piece_size = pieces.ravel()
        end = np.cumsum(piece_size)
        src = np.concatenate((head.view(np.uint8), np.frombuffer(blob, dtype=np.uint8)))
        at = buf.tell()
        self._bulk.append((np.asarray(channel_ids, dtype=np.int64), at + end[0::2] - hs, log_time))
        buf.write(src[np.repeat(piece_start.ravel() - (end - piece_size), piece_size) + np.arange(int(end[-1]))].tobytes())
        if buf.tell() > self._fast_chunk_size:
            self._Writer__finalize_chunk()

    def _count(self, n: int, log_time: int, last_time: int | None = None) -> Any:
        """The file's and the open chunk's statistics of n more messages at `log_time` (as
        `add_message` keeps them; between `log_time` and `last_time` when given); the chunk's buffer."""
        st, cb = self._stats, self._chunk
        hi = log_time if last_time is None else last_time
        for rec, empty in ((st, st.message_count == 0), (cb, cb.num_messages == 0)):
            if empty or log_time < rec.message_start_time:
                rec.message_start_time = log_time
            if hi > rec.message_end_time:
                rec.message_end_time = hi
        st.message_count += n
        cb.num_messages += n
        return cb.record_writer._buffer

    def add_records(self, channel_ids: np.ndarray, log_time: int, records: bytes, starts: np.ndarray) -> None:
        """Message records already made (`BulkRecords`: their sequence numbers and publish time in
        them), all of log time `log_time`, record i at records[starts[i]:] on channel_ids[i]."""
        n = len(channel_ids)
        if n == 0:
            return
        buf = self._count(n, log_time)
        self._bulk.append((channel_ids, buf.tell() + starts, log_time))
        buf.write(records)
        if buf.tell() > self._fast_chunk_size:
            self._Writer__finalize_chunk()

    def _fold(self) -> None:
        """The message index entries and channel counts of the open chunk's `add_messages`."""
        if not self._bulk:
            return
        bulk, self._bulk = self._bulk, []
        cids = np.concatenate([c for c, _a, _t in bulk])
        order = np.argsort(cids, kind="stable")  # (each channel's entries in file order)
        pairs = np.empty((len(cids), 2), dtype=np.int64)  # (log time, offset) of each, by channel
        pairs[:, 0] = np.concatenate([np.full(len(c), t, dtype=np.int64) for c, _a, t in bulk])[order]  # (t: one, or each's)
        pairs[:, 1] = np.concatenate([a for _c, a, _t in bulk])[order]
        flat = pairs.ravel()
        cs = cids[order]
        starts = np.flatnonzero(np.r_[True, cs[1:] != cs[:-1]]).tolist()
        indices, counts = self._chunk.message_indices, self._stats.channel_message_counts
        for a, b, cid in zip(starts, starts[1:] + [len(cs)], cs[starts].tolist()):
            counts[cid] += b - a
            old = indices.get(cid)
            entries = flat[2 * a:2 * b]  # (an array: `_write_pending` packs it as it is)
            if old is not None and len(old):  # (a channel written both ways: its entries in file order)
                old, new = list(old), entries.tolist()
                merged = sorted(zip(old[1::2] + new[1::2], old[0::2] + new[0::2]))
                indices[cid] = [x for off, t in merged for x in (t, off)]
            else:
                indices[cid] = entries

    def _Writer__finalize_chunk(self) -> None:  # noqa: N802 - overrides mcap's private __finalize_chunk
        """mcap 1.6's `Writer.__finalize_chunk` (ZSTD, enable_crcs as given), compressing with this
        writer's zstd compressor instead of `zstandard.compress` at its default level, on a worker
        thread when `background` (zstd releases the GIL): closed chunks wait in order in `_pending`
        and go to the stream when compressed (checked at each new chunk, without waiting) or at the
        next other write to the stream (`_Writer__flush`, waiting), so every record keeps its place
        in the file."""
        if not self._fast:
            return Writer._Writer__finalize_chunk(self)  # type: ignore[attr-defined]
        cb = self._chunk
        if cb.num_messages == 0:
            return
        self._fold()
        if self._Writer__record_builder.count:  # records written since the last chunk go before this one
            self._Writer__flush()
        else:
            while self._pending and self._pending[0][0].done():
                self._write_pending()
        self._stats.chunk_count += 1
        indices, cb.message_indices = cb.message_indices, {}
        data = cb.end()
        crc = self._Writer__enable_crcs
        pending = (cb.message_start_time, cb.message_end_time, len(data), indices)
        if self._pool is not None:
            self._pending.append((self._pool.submit(_compress, self._zstd, data, crc), *pending))
        else:
            self._pending.append((_Done(_compress(self._zstd, data, crc)), *pending))
        cb.reset()

    def _Writer__flush(self) -> None:  # noqa: N802 - overrides mcap's private __flush
        """Write the pending chunks (waiting for their compression) before what the record builder holds."""
        while self._pending:
            self._write_pending()
        Writer._Writer__flush(self)  # type: ignore[attr-defined]

    def _write_pending(self) -> None:
        """The oldest pending chunk's records: Chunk, then its MessageIndex records."""
        future, t0, t1, size, indices = self._pending.popleft()
        compressed, crc = future.result()
        chunk = Chunk(compression="zstd", data=compressed, message_start_time=t0, message_end_time=t1,
                      uncompressed_crc=crc, uncompressed_size=size)
        rb, stream = self._Writer__record_builder, self._Writer__stream
        later = rb.end()  # records added since the chunk was closed: they follow it
        start = stream.tell()
        chunk.write(rb)
        index = ChunkIndex(message_start_time=t0, message_end_time=t1, chunk_start_offset=start, chunk_length=rb.count,
                           message_index_offsets={}, message_index_length=0, compression="zstd",
                           compressed_size=len(compressed), uncompressed_size=size)
        Writer._Writer__flush(self)  # type: ignore[attr-defined]
        index_start = stream.tell()
        if self._Writer__index_types & IndexType.MESSAGE:
            for cid, flat in indices.items():  # MessageIndex records (mcap's MessageIndex.write), one pack each
                index.message_index_offsets[cid] = index_start + rb.count
                n = len(flat)
                if isinstance(flat, np.ndarray):  # (a channel of `add_messages` / `add_records`: `_fold`)
                    rb.write(struct.pack("<BQHI", _OP_MESSAGE_INDEX, 6 + 8 * n, cid, 8 * n) + flat.astype("<u8").tobytes())
                else:
                    rb.write(struct.pack(f"<BQHI{n}Q", _OP_MESSAGE_INDEX, 6 + 8 * n, cid, 8 * n, *flat))
        index.message_index_length = rb.count
        Writer._Writer__flush(self)  # type: ignore[attr-defined]
        self._Writer__chunk_indices.append(index)
        rb.write(later)

    def finish(self) -> None:
        try:
            super().finish()
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=False)


def _compress(zstd: zstandard.ZstdCompressor, data: bytes, crc: bool) -> tuple[bytes, int]:
    return zstd.compress(data), (zlib.crc32(data) if crc else 0)


class _Done:
    """A result already there (no worker thread): what the pending chunk's future gives."""

    def __init__(self, value: Any) -> None:
        self._value = value

    def result(self) -> Any:
        return self._value

    def done(self) -> bool:
        return True


class BulkRecords:
    """The MCAP Message records of a step's messages from several bus/bulk_wire.py encoders,
    interleaved (message r of each encoder in turn, r = 0, 1, ...), in one gather: each record's
    head (opcode, length, channel, sequence, log time, publish time) and its message. The plan of a
    layout (the encoders' layouts and the channels) is kept as theirs are."""

    def __init__(self, pool: Pool) -> None:
        self.pool = pool
        self._plans: dict[tuple, tuple[Gather, np.ndarray, np.ndarray]] = {}
        self.built = 0

    def take(self, parts: list[Prepared], channel_ids: np.ndarray, sequence: int, log_time: int,
             publish_time: int) -> tuple[bytes, np.ndarray, np.ndarray]:
        """(records, each record's start in them, each message's size)."""
        n = len(channel_ids)
        rec = np.empty(n + 4, dtype="<u4")  # the sequence numbers, then the log and publish times
        rec[:n] = np.arange(sequence, sequence + n)
        rec[n:].view("<u8")[:] = (log_time, publish_time)
        chunks = [c for p in parts for c in p.area.chunks()]
        chunks.append(rec.view(np.uint8))
        key = (*(p.key for p in parts), channel_ids.tobytes())
        plan = self._plans.get(key)
        if plan is None:
            if len(self._plans) >= MAX_PLANS:
                for k in list(self._plans)[:MAX_PLANS // 2]:
                    del self._plans[k]
            area_sizes = [sum(len(c) for c in p.area.chunks()) for p in parts] + [4 * len(rec)]
            plan = self._plans[key] = self._plan(parts, area_sizes, channel_ids)
            self.built += 1
        gather, starts, sizes = plan
        return gather(np.concatenate(chunks)), starts, sizes

    def _plan(self, parts: list[Prepared], area_sizes: list[int], channel_ids: np.ndarray
              ) -> tuple[Gather, np.ndarray, np.ndarray]:
        subs = [p.plan() for p in parts]
        n_rows = len(subs[0][1]) - 1
        sources, starts, sizes = [], [], []
        at = base = 0
        for (ids, ends), size in zip(subs, area_sizes):
            sources.append(np.where(ids >= 0, ids + base, ids))  # the part's area ids, in the step's area
            starts.append(ends[:-1] + at)
            sizes.append(ends[1:] - ends[:-1])
            at += len(ids)
            base += size
        m_start = np.stack(starts, axis=1).ravel()  # message r of each part in turn
        m_size = np.stack(sizes, axis=1).ravel()
        n = len(m_size)
        assert n == len(channel_ids) == n_rows * len(parts)
        fixed = np.zeros(n, dtype=[("op", "u1"), ("length", "<u8"), ("channel", "<u2")])
        fixed["op"], fixed["length"], fixed["channel"] = _OP_MESSAGE, _MESSAGE_FIXED + m_size, channel_ids
        rec_base = base  # the sequence numbers' bytes, then the two times'
        heads = np.concatenate((self.pool.block(fixed.view(np.uint8).reshape(n, 11)),
                                rec_base + np.arange(4 * n).reshape(n, 4),
                                np.broadcast_to(rec_base + 4 * n + np.arange(16), (n, 16))), axis=1)
        hs = _MESSAGE.size
        piece_start = np.stack((np.arange(0, n * hs, hs), n * hs + m_start), axis=1).ravel()
        piece_size = np.stack((np.full(n, hs), m_size), axis=1).ravel()
        ids = np.concatenate((heads.ravel(), *sources))[ranges(piece_start, piece_size)]
        rec_size = hs + m_size
        return Gather(ids, self.pool, sum(area_sizes)), np.cumsum(rec_size) - rec_size, m_size
