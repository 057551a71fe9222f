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

from swarmhil.bus.keys import split_topic


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


def segment_name(index: int) -> str:
    """The recording of a run (`run.mcap`), or segment N of it after N recorder restarts (`run.00N.mcap`)."""
    return "run.mcap" if index == 0 else f"run.{index:03d}.mcap"


class _Copier:
    """Copies the readable records of one or more recordings into one writer: schemas and channels
    re-registered once (by content, so the same channel in two segments is one channel), metadata
    and attachments once each, messages in file order with fresh sequence numbers."""

    def __init__(self, w: Writer) -> None:
        self.w = w
        self.schemas: dict[tuple[str, str, bytes], int] = {}
        self.channels: dict[tuple[str, str, int], int] = {}
        self.metadata: set[tuple[str, tuple[tuple[str, str], ...]]] = set()
        self.attachments: set[tuple[str, bytes]] = set()
        self.messages = 0

    def copy(self, src: str | Path) -> dict[str, int | bool]:
        """One file by a linear scan (a file without footer too: STACK-NOTES, only its open chunk is lost)."""
        schema_of: dict[int, int] = {}
        channel_of: dict[int, int] = {}
        n, first, last, truncated = 0, None, None, False
        with open(src, "rb") as fin:
            try:
                for rec in StreamReader(fin, skip_magic=False, emit_chunks=False, validate_crcs=True).records:
                    if isinstance(rec, Schema):
                        key = (rec.name, rec.encoding, bytes(rec.data))
                        if key not in self.schemas:
                            self.schemas[key] = self.w.register_schema(rec.name, rec.encoding, rec.data)
                        schema_of[rec.id] = self.schemas[key]
                    elif isinstance(rec, Channel):
                        sid = schema_of.get(rec.schema_id, 0)
                        ckey = (rec.topic, rec.message_encoding, sid)
                        if ckey not in self.channels:
                            self.channels[ckey] = self.w.register_channel(rec.topic, rec.message_encoding, sid,
                                                                          dict(rec.metadata))
                        channel_of[rec.id] = self.channels[ckey]
                    elif isinstance(rec, Metadata):  # the run id, configuration (describe_run), segment
                        mkey = (rec.name, tuple(sorted(rec.metadata.items())))
                        if mkey not in self.metadata:
                            self.metadata.add(mkey)
                            self.w.add_metadata(rec.name, dict(rec.metadata))
                    elif isinstance(rec, Attachment):
                        akey = (rec.name, bytes(rec.data))
                        if akey not in self.attachments:
                            self.attachments.add(akey)
                            self.w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                    elif isinstance(rec, Message) and rec.channel_id in channel_of:
                        self.w.add_message(channel_of[rec.channel_id], rec.log_time, rec.data, rec.publish_time,
                                           self.messages)
                        self.messages += 1
                        n += 1
                        first = rec.log_time if first is None else min(first, rec.log_time)
                        last = rec.log_time if last is None else max(last, rec.log_time)
            except (McapError, EOFError, ValueError, Exception) as exc:  # the truncated tail
                truncated = not isinstance(exc, StopIteration)
        return {"messages": n, "first_log_time": first or 0, "last_log_time": last or 0, "truncated_tail": truncated}


def repair(src: str | Path, dst: str | Path) -> dict[str, int | bool]:
    """Copy every record a linear scan can read (STACK-NOTES: only the open chunk is lost).

    Schemas and channels are re-registered in the new file; a truncated tail ends the scan.
    """
    with open(dst, "wb") as fout:
        w = Writer(fout, compression=CompressionType.ZSTD)
        w.start(profile="", library="swarmhil-repair")
        c = _Copier(w)
        got = c.copy(src)
        w.finish()
    return {"messages": c.messages, "channels": len(c.channels), "schemas": len(c.schemas),
            "truncated_tail": bool(got["truncated_tail"])}


def merge(srcs: list[str | Path], dst: str | Path) -> dict[str, object]:
    """The segments of one run (a recorder restarted after it was killed: run.mcap, run.001.mcap,
    ...) as one file. Each segment is read by a linear scan (a killed writer's file too); the
    metadata `swarmhil.segments` lists each segment's message count and log-time span, so the gaps
    between them stay visible. Messages keep their log times; readers order them by log time."""
    import json

    segs = []
    with open(dst, "wb") as fout:
        w = Writer(fout, compression=CompressionType.ZSTD)
        w.start(profile="", library="swarmhil-merge")
        c = _Copier(w)
        for src in srcs:
            segs.append({"file": Path(src).name, **c.copy(src)})
        w.add_metadata("swarmhil.segments", {"json": json.dumps(segs)})
        w.finish()
    return {"messages": c.messages, "channels": len(c.channels), "segments": segs}


def topic_counts(path: str | Path) -> Counter[str]:
    with open(path, "rb") as f:
        r = make_reader(f)
        s = r.get_summary()
        if s is not None and s.statistics is not None:
            return Counter({s.channels[cid].topic: n for cid, n in s.statistics.channel_message_counts.items()})
        return Counter(ch.topic for _s, ch, _m in r.iter_messages())
