"""bus/mcap_writer.py: the recorder's fast MCAP writer writes what mcap's own Writer writes (issue 16)."""
from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from swarmhil.bus.mcap_writer import ZSTD_LEVEL, RecorderWriter


def _write(w: Writer, rng: np.random.Generator, n: int) -> None:
    """Schemas, channels, metadata, an attachment and n messages of random sizes and log times
    (not monotonic, equal ones too), with a flush in the middle."""
    w.start(profile="", library="swarmhil")
    s1 = w.register_schema(name="a.A", encoding="protobuf", data=b"\x01\x02")
    s2 = w.register_schema(name="b.B", encoding="protobuf", data=b"\x03")
    chans = [w.register_channel(topic=t, message_encoding="protobuf", schema_id=s)
             for t, s in (("truth", s1), ("event", s2), ("sc/sc01/act", s1))]
    w.add_metadata("swarmhil.run", {"run": "r"})
    w.add_attachment(create_time=1, log_time=0, name="scenario.json", media_type="application/json", data=b"{}")
    t = 10**18
    for i in range(n):
        t += int(rng.integers(-5, 10**7))
        size = int(rng.choice([0, 1, 200, 3500, 70000]))
        w.add_message(channel_id=chans[int(rng.integers(len(chans)))], log_time=t, data=rng.bytes(size // 4) * 4 + bytes(size % 4),
                      publish_time=int(rng.integers(0, 2**63)), sequence=i)
        if i == n // 2:
            w.flush()
    w.finish()


@pytest.mark.parametrize("chunk_size", [1, 4096, 256 * 1024])
def test_same_file_as_mcaps_writer_at_the_same_level(chunk_size: int) -> None:
    """At zstd level 3 (mcap's default) the file is byte for byte the one mcap's Writer writes, also
    with the chunks compressed on a worker thread (their records written later, in their place)."""
    files = []
    for make in (lambda f: Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD),
                 lambda f: RecorderWriter(f, chunk_size=chunk_size, zstd_level=3),
                 lambda f: RecorderWriter(f, chunk_size=chunk_size, zstd_level=3, background=True)):
        f = io.BytesIO()
        w = make(f)
        _write(w, np.random.default_rng(chunk_size), 300)
        files.append(f.getvalue())
    assert isinstance(RecorderWriter(io.BytesIO(), 1), Writer) and RecorderWriter(io.BytesIO(), 1)._fast
    assert files[0] == files[1] == files[2]


def test_its_own_level_reads_back_with_the_standard_readers() -> None:
    """At the recorder's level the chunks differ, and every record reads back the same: messages
    in order with their channel, times, sequence and bytes, the summary, indexes and statistics."""
    out = {}
    for name, make in (("mcap", lambda f: Writer(f, chunk_size=8192, compression=CompressionType.ZSTD)),
                       ("fast", lambda f: RecorderWriter(f, chunk_size=8192)),
                       ("background", lambda f: RecorderWriter(f, chunk_size=8192, background=True))):
        f = io.BytesIO()
        _write(make(f), np.random.default_rng(7), 400)
        out[name] = f.getvalue()
    assert ZSTD_LEVEL != 3 and out["mcap"] != out["fast"] == out["background"]
    seen = {}
    for name, data in out.items():
        r = make_reader(io.BytesIO(data))
        summ = r.get_summary()
        msgs = [(c.topic, m.log_time, m.publish_time, m.sequence, m.data) for _, c, m in r.iter_messages(log_time_order=False)]
        in_time = [m.sequence for _, _, m in r.iter_messages(log_time_order=True)]
        one = [m.sequence for _, _, m in r.iter_messages(topics=["event"], starting_at=10**18 + 10**9)]
        recs = [type(x).__name__ for x in StreamReader(io.BytesIO(data), validate_crcs=True).records]
        seen[name] = (msgs, in_time, one, summ.statistics, len(summ.chunk_indexes), recs,
                      [m.name for m in r.iter_metadata()], [a.name for a in r.iter_attachments()])
    assert len(seen["fast"][0]) == 400 and seen["fast"][2]
    assert seen["fast"] == seen["mcap"] == seen["background"]
