"""MCAP utilities: repair of a recording whose writer was killed, counts per topic, and the
readers' view of topics: current recordings have relative topics (`truth`, `sc/sc01/act`) and the
run id in the metadata `swarmhil.run`; recordings made before the MCAP contract carried the whole
key (`swarm/<run>/truth`). `relative_topic` and `run_of_recording` accept both."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from bus.keys import split_topic


def relative_topic(topic: str) -> str:
    """`truth` for both `truth` and the old `swarm/<run>/truth`."""
    return split_topic(topic)[1]


def find_topic(topics, rel: str, run: str | None = None) -> list[str]:  # type: ignore[no-untyped-def]
    """The topics of a recording that are `rel` (new) or `swarm/<run>/rel` (old; any run if run is None)."""
    out = []
    for t in topics:
        r, tail = split_topic(t)
        if tail == rel and (r is None or run is None or r == run):
            out.append(t)
    return sorted(out)


def run_of_recording(reader) -> str | None:  # type: ignore[no-untyped-def]
    """The run id of an open recording: metadata `swarmhil.run`, else the prefix of old topics."""
    try:
        for meta in reader.iter_metadata():
            if meta.name == "swarmhil.run" and meta.metadata.get("run"):
                return str(meta.metadata["run"])
    except (McapError, EOFError, ValueError, KeyError):
        pass
    summary = reader.get_summary()
    runs = sorted({r for ch in summary.channels.values() if (r := split_topic(ch.topic)[0])}) if summary else []
    return runs[0] if len(runs) == 1 else None


def repair(src: str | Path, dst: str | Path) -> dict[str, int | bool]:
    """Copy every record a linear scan can read (STACK-NOTES: only the open chunk is lost).

    Schemas and channels are re-registered in the new file; a truncated tail ends the scan.
    """
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    messages = 0
    truncated = False
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        w = Writer(fout, compression=CompressionType.ZSTD)
        w.start(profile="", library="swarmhil-repair")
        try:
            for rec in StreamReader(fin, skip_magic=False, emit_chunks=False, validate_crcs=True).records:
                if isinstance(rec, Schema):
                    if rec.id not in schemas:
                        schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
                elif isinstance(rec, Channel):
                    if rec.id not in channels:
                        channels[rec.id] = w.register_channel(rec.topic, rec.message_encoding,
                                                              schemas.get(rec.schema_id, 0), dict(rec.metadata))
                elif isinstance(rec, Metadata):  # the run id, configuration (describe_run)
                    w.add_metadata(rec.name, dict(rec.metadata))
                elif isinstance(rec, Attachment):
                    w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                elif isinstance(rec, Message):
                    if rec.channel_id in channels:
                        w.add_message(channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time, rec.sequence)
                        messages += 1
        except (McapError, EOFError, ValueError, Exception) as exc:  # the truncated tail
            truncated = not isinstance(exc, StopIteration)
        w.finish()
    return {"messages": messages, "channels": len(channels), "schemas": len(schemas), "truncated_tail": truncated}


def topic_counts(path: str | Path) -> Counter[str]:
    with open(path, "rb") as f:
        r = make_reader(f)
        s = r.get_summary()
        if s is not None and s.statistics is not None:
            return Counter({s.channels[cid].topic: n for cid, n in s.statistics.channel_message_counts.items()})
        return Counter(ch.topic for _s, ch, _m in r.iter_messages())
