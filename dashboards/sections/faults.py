"""Report section `faults` (issue 27): the run's `[[fault]]` schedule and when each fault started and
ended, read from the recording's `faults` topic (Events fault_start / fault_end, plant/node.py)."""
from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from dashboards.sections import SectionContext, SectionResult, register_section


def read_events(mcap: Path, topic: str, kinds: tuple[str, ...] | None = None) -> list[Any]:
    """The swarmhil.v1.Event messages of one topic (`event`, `faults`), in log-time order, with the
    standard reader; `kinds`: only those."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(mcap, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m for _s, _c, _msg, m in reader.iter_decoded_messages(topics=[topic])
                if kinds is None or m.kind in kinds]


def table(head: list[str], rows: list[list[Any]]) -> str:
    """An escaped HTML table."""
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    trs = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{trs}</table>"


@register_section("faults", applies=lambda cfg: bool(cfg.get("faults")))
def faults(ctx: SectionContext) -> SectionResult:
    events = read_events(ctx.mcap, "faults", ("fault_start", "fault_end"))
    seen: dict[str, dict[str, Any]] = {}
    for e in events:
        seen.setdefault(e.subject, {})[e.kind] = round(e.header.t, 9)
    rows, metrics = [], {}
    for f in ctx.config["faults"]:
        name = f["name"]
        what = {k: v for k, v in f.items() if k not in ("name", "kind", "start_s", "end_s")}
        started, ended = seen.get(name, {}).get("fault_start"), seen.get(name, {}).get("fault_end")
        rows.append([name, f["kind"], json.dumps(what), f["start_s"], f["end_s"] if f["end_s"] is not None else "run end",
                     "no" if started is None else started, "-" if ended is None else ended])
        metrics[name] = {"kind": f["kind"], "started_t_s": started, "ended_t_s": ended}
    intro = (f"<p>{len(ctx.config['faults'])} faults scheduled (docs/faults.md); started and ended: the simulated times "
             f"of their events on the recording's <code>faults</code> topic.</p>")
    return SectionResult("Faults", metrics, [], intro + table(
        ["fault", "kind", "target and parameters", "start [s]", "end [s]", "started at [s]", "ended at [s]"], rows))
