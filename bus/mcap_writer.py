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

import zstandard
from mcap.records import Chunk, ChunkIndex
from mcap.writer import CompressionType, IndexType, Writer

ZSTD_LEVEL = 1
_MESSAGE = struct.Struct("<BQHIQQ")  # opcode 0x05, record length, channel id, sequence, log time, publish time
_OP_MESSAGE = 0x05
_OP_MESSAGE_INDEX = 0x07
_MESSAGE_FIXED = 2 + 4 + 8 + 8  # the record's bytes before its data


class RecorderWriter(Writer):
    """`mcap.writer.Writer` (chunked, zstd, every index) with the fast paths above."""

    def __init__(self, output: IO[Any], chunk_size: int, zstd_level: int = ZSTD_LEVEL, background: bool = False) -> None:
        self._pending: deque[tuple] = deque()  # closed chunks, in order: (future, start, end, size, message indexes)
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
        index += (log_time, buf.tell())
        cb.num_messages += 1
        buf.write(_MESSAGE.pack(_OP_MESSAGE, _MESSAGE_FIXED + len(data), channel_id, sequence, log_time, publish_time))
        buf.write(data)
        if buf.tell() > self._fast_chunk_size:
            self._Writer__finalize_chunk()

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
