"""Bandwidth report of a run (issue 5): what the swarm's inter-satellite traffic cost, from the MCAP alone.

Read with the public contract only (the `mcap` reader and the `mcap-protobuf-support` decoder,
which decodes from the schemas embedded in the file): every `isl/tx/<id>` sample (what the agents
offered to their radios), every `isl/rx/<id>` sample (what the channel delivered), every
`link/stats` (the channel's own cumulative counters), the channel's `link_config` event and the
truth (positions at the time of sending, for an independent range check).

Two independent accountings are compared and must agree exactly: bytes and messages counted in
the recording (tx samples the channel accepts by the rules of link/model.py `check_tx`, and rx
samples) against the channel's counters (the last `LinkStats` of the recording and
`summary.json["channel"]`). Bytes with overhead = payload + the configured per-packet overhead.

Figures (matplotlib, PNG next to the HTML): cumulative bytes and messages per agent over time,
the link matrix (delivered bytes, transmitter x receiver), drops by cause per transmitter. A
comparison mode puts two runs side by side (e.g. periodic versus event-triggered broadcasting).
"""
from __future__ import annotations

import html
import json
import math
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bus.keys import split_topic
from bus.mcap_tools import run_of_recording
from dashboards.figstyle import Line, LineFigure, Panel, colors, integer_axis, legend
from dashboards.figstyle import pyplot as _plt
from dashboards.figstyle import save as _save
from dashboards.figstyle import time_axis as _time_axis
from dashboards.interactive import plotly_div
from dashboards.kit import bar_for, figure_html, render, static_figure
from link.model import COUNTER_FIELDS, DROP_CAUSES, TX_ROW, check_tx, line_of_sight_clear, reason_class


@dataclass
class LinkTraffic:
    """Everything of one run the bandwidth report needs, decoded from its recording."""

    run: str
    ids: list[str]
    config: dict[str, Any]
    step_s: float
    t_end_s: float = 0.0
    # accepted transmissions: (t, src, dst, type, payload_bytes)
    tx: list[tuple[float, str, str, str, int]] = field(default_factory=list)
    # deliveries: (t_rx, sent_t, src, receiver, type, payload_bytes)
    rx: list[tuple[float, float, str, str, str, int]] = field(default_factory=list)
    rejected_tx: Counter = field(default_factory=Counter)       # reason class -> count (from the MCAP)
    rejected_events: int = 0
    stats_rows: dict[tuple[str, str, str], list[int]] = field(default_factory=dict)  # last LinkStats
    stats_rejected: int | None = None
    stats_tx_messages: int | None = None
    stats_rx_messages: int | None = None
    stats_t_s: float | None = None
    stats_series: list[tuple[float, dict[str, int]]] = field(default_factory=list)
    beyond_range: int = 0          # deliveries to a receiver out of range at the time of sending
    occulted_delivered: int = 0    # deliveries through the Earth
    unchecked_geometry: int = 0    # deliveries whose sending-time truth is not in the recording
    summary_channel: dict[str, Any] | None = None

    @property
    def has_link(self) -> bool:
        """False for a run without the link channel (no [link] in its scenario): no link configuration,
        no transmission, delivery or counter in the recording or the summary."""
        return bool(set(self.config) - {"ids"} or self.tx or self.rx or self.rejected_tx or self.stats_series
                    or self.summary_channel)

    @property
    def overhead_bytes(self) -> int:
        return int(self.config.get("overhead_bytes", 0))


def _topic_kind(topic: str) -> tuple[str, str | None]:
    """Kind and id of an MCAP topic: `isl/tx/sc01` (or the old `swarm/<run>/isl/tx/sc01`)."""
    parts = split_topic(topic)[1].split("/")
    if len(parts) == 3 and parts[0] == "isl" and parts[1] in ("tx", "rx"):
        return f"isl_{parts[1]}", parts[2]
    if parts == ["link", "stats"]:
        return "link_stats", None
    if len(parts) == 1 and parts[0] in ("truth", "event"):
        return parts[0], None
    return "other", None


def _finite(*xs: float) -> bool:
    return all(math.isfinite(x) for x in xs)


def read_link_traffic(run_dir: str | Path) -> LinkTraffic:
    """Decode the link traffic of run_dir/run.mcap (and read run_dir/summary.json when present)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    run_dir = Path(run_dir)
    spath = run_dir / "summary.json"
    summary = json.loads(spath.read_text()) if spath.is_file() else {}
    run = summary.get("run")
    truth: dict[int, tuple[dict[str, np.ndarray], float]] = {}
    tx_raw: list[tuple[str, Any, str]] = []   # (key id, decoded msg, schema name)
    rx_raw: list[tuple[str, Any]] = []
    config: dict[str, Any] | None = None
    stats_series: list[tuple[float, Any]] = []
    rejected_events = 0
    t_end = 0.0
    with open(run_dir / "run.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        s = reader.get_summary()
        topics = sorted({ch.topic for ch in s.channels.values()}) if s is not None else []
        if run is None:
            run = run_of_recording(reader)
            if run is None:
                raise ValueError(f"{run_dir}: cannot tell the run id (no swarmhil.run metadata, no single swarm/<run>/ prefix)")

        wanted = [t for t in topics if split_topic(t)[0] in (None, run) and _topic_kind(t)[0] in
                  ("isl_tx", "isl_rx", "link_stats", "truth", "event")]
        for schema, channel, message, msg in reader.iter_decoded_messages(topics=wanted):
            kind, key_id = _topic_kind(channel.topic)
            if kind == "truth":
                pos = {b.id: np.array([b.position_m.x, b.position_m.y, b.position_m.z]) for b in msg.bodies}
                truth[int(round(msg.header.t * 1000))] = (pos, msg.semi_major_axis_m)
                t_end = max(t_end, msg.header.t)
            elif kind == "isl_tx":
                tx_raw.append((key_id, msg, schema.name))
            elif kind == "isl_rx":
                rx_raw.append((key_id, msg))
            elif kind == "link_stats":
                stats_series.append((msg.header.t, msg))
            elif kind == "event" and msg.header.source == "channel":
                if msg.kind == "link_config":
                    config = json.loads(msg.detail)
                elif msg.kind == "rejected_packet":
                    rejected_events += 1
    if config is None:
        config = dict((summary.get("channel") or {}).get("config") or {})
        config.setdefault("ids", [])
    ids = list(config.get("ids") or sorted({i for p, _a in truth.values() for i in p}))
    step_s = float(config.get("step_s", summary.get("step_s", 1.0)))
    lt = LinkTraffic(run=run, ids=ids, config=config, step_s=step_s, t_end_s=t_end,
                     rejected_events=rejected_events, summary_channel=summary.get("channel"))
    known = set(ids)
    max_payload = int(config.get("max_payload_bytes", 1 << 62))
    for key_id, m, schema_name in tx_raw:
        if schema_name != "swarmhil.v1.IslPacket":
            lt.rejected_tx["malformed"] += 1
            continue
        if m.header.run != run or not _finite(m.header.t, m.sent_t):
            lt.rejected_tx["malformed"] += 1
            continue
        reason = check_tx(key_id, m.src, m.dst, len(m.payload), known, max_payload)
        if reason:
            lt.rejected_tx[reason_class(reason)] += 1
            continue
        lt.tx.append((m.header.t, m.src, m.dst, m.type, len(m.payload)))
    range_m = float(config.get("range_m", math.inf))
    occ = bool(config.get("occultation", False))
    r_block = float(config.get("earth_radius_m", 6378137.0)) + float(config.get("grazing_altitude_m", 0.0))
    for key_id, m in rx_raw:
        lt.rx.append((m.header.t, m.sent_t, m.src, key_id, m.type, len(m.payload)))
        at = truth.get(int(round(m.sent_t * 1000)))
        if at is None or m.src not in at[0] or key_id not in at[0]:
            lt.unchecked_geometry += 1
            continue
        p1, p2 = at[0][m.src], at[0][key_id]
        if float(np.linalg.norm(p2 - p1)) > range_m:
            lt.beyond_range += 1
        if occ and not line_of_sight_clear(p1, p2, at[1], r_block):
            lt.occulted_delivered += 1
    for t, st in stats_series:
        lt.stats_series.append((t, {"tx_messages": st.tx_messages, "rx_messages": st.rx_messages,
                                    **{f"dropped_{c}": sum(getattr(c_, f"dropped_{c}") for c_ in st.links)
                                       for c in DROP_CAUSES}}))
    if stats_series:
        t, last = stats_series[-1]
        lt.stats_t_s = t
        lt.stats_rejected = int(last.rejected_packets)
        lt.stats_tx_messages = int(last.tx_messages)
        lt.stats_rx_messages = int(last.rx_messages)
        lt.stats_rows = {(c.src, c.dst, c.type): [int(getattr(c, n)) for n in COUNTER_FIELDS] for c in last.links}
    return lt


# --- accounting --------------------------------------------------------------------------------------
_MSG, _PAY, _WIRE = 0, 1, 2


def mcap_rows(lt: LinkTraffic) -> dict[tuple[str, str, str], list[int]]:
    """Counters (messages, payload bytes, wire bytes) per (src, dst, type) counted from the recording."""
    rows: dict[tuple[str, str, str], list[int]] = defaultdict(lambda: [0, 0, 0])
    ov = lt.overhead_bytes
    for _t, src, _dst, typ, n in lt.tx:
        r = rows[(src, TX_ROW, typ)]
        r[0] += 1
        r[1] += n
        r[2] += n + ov
    for _t, _ts, src, dst, typ, n in lt.rx:
        r = rows[(src, dst, typ)]
        r[0] += 1
        r[1] += n
        r[2] += n + ov
    return dict(rows)


def _totals_of(rows: dict[tuple[str, str, str], list[int]]) -> dict[str, int]:
    out = {f"{d}_{n}": 0 for d in ("tx", "rx") for n in ("messages", "payload_bytes", "wire_bytes")}
    for (_s, dst, _t), r in rows.items():
        side = "tx" if dst == TX_ROW else "rx"
        out[f"{side}_messages"] += r[0]
        out[f"{side}_payload_bytes"] += r[1]
        out[f"{side}_wire_bytes"] += r[2]
    return out


def totals(lt: LinkTraffic) -> dict[str, Any]:
    """The headline numbers from the recording, and from the channel's counters, side by side."""
    from_mcap = _totals_of(mcap_rows(lt))
    from_mcap["rejected_packets"] = sum(lt.rejected_tx.values())
    from_stats: dict[str, int] | None = None
    if lt.stats_rows:
        from_stats = _totals_of({k: v[:3] for k, v in lt.stats_rows.items()})
        from_stats["rejected_packets"] = int(lt.stats_rejected or 0)
        for i, c in enumerate(DROP_CAUSES):
            from_stats[f"dropped_{c}"] = sum(v[3 + i] for v in lt.stats_rows.values())
    from_summary = None
    if lt.summary_channel and "totals" in lt.summary_channel:
        from_summary = {k: int(v) for k, v in lt.summary_channel["totals"].items()}
    lat = np.array([t - ts for t, ts, *_ in lt.rx]) if lt.rx else np.zeros(0)
    return {"mcap": from_mcap, "link_stats": from_stats, "summary": from_summary,
            "latency_s": {"mean": float(lat.mean()) if lat.size else None, "max": float(lat.max()) if lat.size else None},
            "geometry": {"beyond_range": lt.beyond_range, "occulted_delivered": lt.occulted_delivered,
                         "unchecked": lt.unchecked_geometry}}


def consistency(lt: LinkTraffic) -> list[tuple[str, Any, Any, Any, bool]]:
    """(quantity, recording, last LinkStats, summary.json, all equal) for each checked number,
    plus one row for the per-link table as a whole."""
    tot = totals(lt)
    out = []
    for k in ("tx_messages", "tx_payload_bytes", "tx_wire_bytes", "rx_messages", "rx_payload_bytes", "rx_wire_bytes",
              "rejected_packets"):
        a = tot["mcap"][k]
        b = tot["link_stats"][k] if tot["link_stats"] else None
        c = tot["summary"].get(k) if tot["summary"] else None
        out.append((k, a, b, c, a == b and (c is None or a == c)))
    for c in DROP_CAUSES:
        k = f"dropped_{c}"
        b = tot["link_stats"][k] if tot["link_stats"] else None
        s = tot["summary"].get(k) if tot["summary"] else None
        out.append((k, "-", b, s, b is not None and (s is None or b == s)))
    rows = mcap_rows(lt)
    stats3 = {k: v[:3] for k, v in lt.stats_rows.items() if any(v[:3])}
    summ = None
    if lt.summary_channel and "links" in lt.summary_channel:
        summ = {(r[0], r[1], r[2]): list(r[3:]) for r in lt.summary_channel["links"]}
    same_links = rows == stats3 and (summ is None or summ == lt.stats_rows)
    out.append(("per-link rows (src, dst, type)", len(rows), len(lt.stats_rows), None if summ is None else len(summ), same_links))
    return out


def per_agent_series(lt: LinkTraffic, bin_s: float) -> dict[str, Any]:
    """Bytes with overhead and messages per agent and time bin: tx (by sender), rx (by receiver)."""
    t_end = max([lt.t_end_s] + [r[0] for r in lt.rx] + [r[0] for r in lt.tx] + [0.0])
    edges = np.arange(0.0, t_end + bin_s, bin_s)
    if edges.size < 2:
        edges = np.array([0.0, bin_s])
    n_bins = edges.size - 1
    idx = {s: i for i, s in enumerate(lt.ids)}
    out = {k: np.zeros((len(lt.ids), n_bins)) for k in ("tx_bytes", "tx_msgs", "rx_bytes", "rx_msgs")}
    ov = lt.overhead_bytes
    for t, src, _d, _ty, n in lt.tx:
        b = min(int(t // bin_s), n_bins - 1)
        if src in idx:
            out["tx_bytes"][idx[src], b] += n + ov
            out["tx_msgs"][idx[src], b] += 1
    for t, _ts, _s, dst, _ty, n in lt.rx:
        b = min(int(t // bin_s), n_bins - 1)
        if dst in idx:
            out["rx_bytes"][idx[dst], b] += n + ov
            out["rx_msgs"][idx[dst], b] += 1
    out["edges_s"] = edges
    return out


def link_matrix(lt: LinkTraffic) -> np.ndarray:
    """Delivered bytes with overhead, [transmitter, receiver], from the recording."""
    idx = {s: i for i, s in enumerate(lt.ids)}
    m = np.zeros((len(lt.ids), len(lt.ids)))
    ov = lt.overhead_bytes
    for _t, _ts, src, dst, _ty, n in lt.rx:
        if src in idx and dst in idx:
            m[idx[src], idx[dst]] += n + ov
    return m


def drops_by_transmitter(lt: LinkTraffic) -> dict[str, np.ndarray]:
    """Drops per cause and transmitter, from the channel's counters (the recording's last LinkStats)."""
    idx = {s: i for i, s in enumerate(lt.ids)}
    out = {c: np.zeros(len(lt.ids), dtype=np.int64) for c in DROP_CAUSES}
    for (src, _dst, _ty), v in lt.stats_rows.items():
        if src in idx:
            for i, c in enumerate(DROP_CAUSES):
                out[c][idx[src]] += v[3 + i]
    return out


# --- figures -----------------------------------------------------------------------------------------
def fig_per_agent(lt: LinkTraffic, path: Path, bin_s: float) -> str:
    plt = _plt()
    s = per_agent_series(lt, bin_s)
    x, xl = _time_axis(s["edges_s"][1:])
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    cmap = plt.get_cmap("tab20")
    for (key, title), ax in zip([("tx_bytes", "sent, bytes with overhead (cumulative)"),
                                 ("rx_bytes", "received, bytes with overhead (cumulative)"),
                                 ("tx_msgs", "sent, messages (cumulative)"),
                                 ("rx_msgs", "received, messages (cumulative)")], axes.ravel()):
        for i, sid in enumerate(lt.ids):
            ax.plot(x, np.cumsum(s[key][i]), color=cmap(i % 20), lw=1, label=sid)
        ax.set_title(title)
        ax.set_xlabel(xl)
    legend(axes[0, 1], len(lt.ids))
    for ax in axes[1]:
        integer_axis(ax.yaxis)
    fig.suptitle(f"Link traffic per agent: {lt.run}")
    return _save(fig, path)


def spec_per_agent(lt: LinkTraffic, bin_s: float):  # type: ignore[no-untyped-def]
    """fig_per_agent's lines as a LineFigure (dashboards/figstyle.py), for the interactive version."""
    s = per_agent_series(lt, bin_s)
    x, xl = _time_axis(s["edges_s"][1:])
    cols = colors(len(lt.ids))
    panels = [Panel([Line(x, np.cumsum(s[key][i]), sid, cols[i], 1.0) for i, sid in enumerate(lt.ids)], label,
                    title=title, integer_y=True, xlabel=xl if key == "rx_msgs" else "")
              for key, label, title in [("tx_bytes", "bytes", "sent, bytes with overhead (cumulative)"),
                                        ("rx_bytes", "bytes", "received, bytes with overhead (cumulative)"),
                                        ("tx_msgs", "messages", "sent, messages (cumulative)"),
                                        ("rx_msgs", "messages", "received, messages (cumulative)")]]
    return LineFigure(panels, title=f"Link traffic per agent: {lt.run}")


def fig_rate(lt: LinkTraffic, path: Path, bin_s: float) -> str:
    plt = _plt()
    s = per_agent_series(lt, bin_s)
    x, xl = _time_axis(s["edges_s"][1:])
    fig, ax = plt.subplots(figsize=(12, 3.5))
    ax.step(x, s["tx_bytes"].sum(0) * 8 / bin_s, where="pre", label="offered by all transmitters")
    ax.step(x, s["rx_bytes"].sum(0) * 8 / bin_s, where="pre", label="delivered to all receivers")
    ax.set_ylabel(f"bit/s (mean over {bin_s:g} s)")
    ax.set_xlabel(xl)
    ax.legend()
    ax.set_title("Swarm link load (bytes with overhead)")
    return _save(fig, path)


def fig_matrix(lt: LinkTraffic, path: Path | None, vmax: float | None = None, ax: Any = None) -> str:
    """Heat map of link_matrix; saved to path, or drawn into ax (then path is unused)."""
    plt = _plt()
    m = link_matrix(lt)
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(7.5, 6.5))
    else:
        fig = ax.figure
    im = ax.imshow(m, cmap="viridis", vmin=0, vmax=vmax if vmax is not None else max(m.max(), 1.0))
    ax.set_xticks(range(len(lt.ids)), lt.ids, rotation=90, fontsize=7)
    ax.set_yticks(range(len(lt.ids)), lt.ids, fontsize=7)
    ax.set_xlabel("receiver")
    ax.set_ylabel("transmitter")
    ax.grid(False)
    ax.set_title(f"Delivered bytes with overhead: {lt.run}", fontsize=9)
    fig.colorbar(im, ax=ax, label="bytes")
    return _save(fig, path) if own and path is not None else ""


def fig_drops(lt: LinkTraffic, path: Path) -> str:
    plt = _plt()
    d = drops_by_transmitter(lt)
    fig, ax = plt.subplots(figsize=(12, 3.8))
    x = np.arange(len(lt.ids))
    bottom = np.zeros(len(lt.ids))
    for c in DROP_CAUSES:
        ax.bar(x, d[c], bottom=bottom, label=c)
        bottom += d[c]
    ax.set_xticks(x, lt.ids, rotation=90, fontsize=7)
    ax.set_ylabel("drops (packet x receiver; queue: packets)")
    integer_axis(ax.yaxis)
    ax.set_title("Drops by cause per transmitter (channel counters)")
    ax.legend()
    return _save(fig, path)


# --- HTML --------------------------------------------------------------------------------------------
def _num(v: Any) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, int) and not isinstance(v, bool):
        return f"{v:,}"
    return html.escape(str(v))


def _ok(b: bool) -> str:
    return '<span class="ok">yes</span>' if b else '<span class="bad">NO</span>'


def _table(head: list[str], rows: list[list[Any]], left: int = 1) -> str:
    th = "".join(f'<th class="{"l" if i < left else ""}">{html.escape(h)}</th>' for i, h in enumerate(head))
    body = "".join("<tr>" + "".join(f'<td class="{"l" if i < left else ""}">{c if isinstance(c, str) and c.startswith("<") else _num(c)}</td>'
                                    for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _page(title: str, body: str, out: Path) -> Path:
    """The page, with the report site's link bar when it joins a site (RUN/report/bandwidth.html)."""
    return render("page.html", out, title=title, intro=body, pages=bar_for(out))


def _bin_s(lt: LinkTraffic) -> float:
    dur = max(lt.t_end_s, lt.step_s)
    return max(lt.step_s, float(lt.config.get("stats_period_s", 60.0)) if dur <= 6 * 3600 else dur / 200.0)


def per_link_table(lt: LinkTraffic) -> list[list[Any]]:
    """Rows (src, dst, type, messages, payload bytes, wire bytes, drops by cause) of the channel's
    counters, dst "*" being the transmitter's own row (offered, queue drops)."""
    return [[s, d, t, *v] for (s, d, t), v in sorted(lt.stats_rows.items())]


def bandwidth_section(lt: LinkTraffic, out_dir: Path, prefix: str = "bandwidth_", interactive: bool = False) -> str:
    """The report's HTML body (figures written into out_dir): usable as a section of the main report.
    With `interactive`, the per-agent traffic is a Plotly figure (the page must load plotly.js)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    tot = totals(lt)
    bin_s = _bin_s(lt)
    checks = consistency(lt)
    all_ok = all(c[-1] for c in checks)
    m = tot["mcap"]
    dur = max(lt.t_end_s, 1e-9)
    n = max(len(lt.ids), 1)
    cfg = {k: v for k, v in lt.config.items() if k != "ids"}
    geo = tot["geometry"]
    head = [
        ["run", lt.run], ["spacecraft", len(lt.ids)], ["simulated time [h]", lt.t_end_s / 3600.0],
        ["transmissions (accepted)", m["tx_messages"]], ["  payload bytes / with overhead",
                                                          f"{m['tx_payload_bytes']:,} / {m['tx_wire_bytes']:,}"],
        ["  mean per spacecraft [bit/s with overhead]", m["tx_wire_bytes"] * 8 / dur / n],
        ["deliveries", m["rx_messages"]], ["  payload bytes / with overhead",
                                           f"{m['rx_payload_bytes']:,} / {m['rx_wire_bytes']:,}"],
        ["delivery latency mean / max [s]", f"{_num(tot['latency_s']['mean'])} / {_num(tot['latency_s']['max'])}"],
        ["drops: range / occulted / lost / queue",
         " / ".join(_num((tot["link_stats"] or {}).get(f"dropped_{c}")) for c in DROP_CAUSES)],
        ["rejected packets (recording / channel)", f"{m['rejected_packets']:,} / {_num((tot['link_stats'] or {}).get('rejected_packets'))}"
         + (f" ({', '.join(f'{k}: {v}' for k, v in sorted(lt.rejected_tx.items()))})" if lt.rejected_tx else "")],
        ["deliveries beyond range at sending time (recording)", f"{geo['beyond_range']} " + _ok(geo["beyond_range"] == 0)],
        ["deliveries through the Earth (recording)", f"{geo['occulted_delivered']} " + _ok(geo["occulted_delivered"] == 0)],
        ["deliveries without sending-time truth", geo["unchecked"]],
        ["recording and channel counters agree", _ok(all_ok)],
    ]
    body = _table(["", ""], head, left=1)
    body += "<h2>Totals: recording vs the channel's own counters</h2>"
    body += _table(["quantity", "recording (MCAP samples)", "last LinkStats", "summary.json", "agree"],
                   [[q, a, b, c, _ok(ok)] for q, a, b, c, ok in checks])
    body += f"<details><summary>link configuration</summary><pre>{html.escape(json.dumps(cfg, indent=1))}</pre></details>"
    figs = [
        (fig_per_agent(lt, out_dir / f"{prefix}per_agent.png", bin_s),
         f"Cumulative bytes (with {lt.overhead_bytes} B overhead per packet) and messages per agent, from the recording."),
        (fig_rate(lt, out_dir / f"{prefix}rate.png", bin_s), f"Swarm load in {bin_s:g} s bins."),
        (fig_matrix(lt, out_dir / f"{prefix}matrix.png"), "Link matrix: delivered bytes per (transmitter, receiver)."),
        (fig_drops(lt, out_dir / f"{prefix}drops.png"), "Drops by cause per transmitter."),
    ]
    shown = [static_figure(out_dir, f, c) for f, c in figs]
    if interactive:
        shown[0].div = plotly_div(spec_per_agent(lt, bin_s), f"plot-{prefix}per-agent")
    body += "".join(figure_html(f) for f in shown)
    rows = per_link_table(lt)
    body += (f"<h2>Per link and message type (channel counters)</h2><p>dst <code>{TX_ROW}</code>: what the "
             "transmitter offered to its radio (and its queue drops); other rows: deliveries and drops per receiver.</p>")
    body += _table(["src", "dst", "type", *COUNTER_FIELDS], rows, left=3)
    return body


def _load(run: str | Path | LinkTraffic) -> LinkTraffic:
    return run if isinstance(run, LinkTraffic) else read_link_traffic(run)


def write_bandwidth_report(run_dir: str | Path, out_html: str | Path | None = None, *,
                           traffic: LinkTraffic | None = None) -> Path:
    """Bandwidth report of one run (default run_dir/report/bandwidth.html, PNGs beside it).

    `traffic`: the run's LinkTraffic when already read (read_link_traffic), to read the MCAP once."""
    run_dir = Path(run_dir)
    out_html = Path(out_html) if out_html else run_dir / "report" / "bandwidth.html"
    out_html.parent.mkdir(parents=True, exist_ok=True)
    lt = traffic or read_link_traffic(run_dir)
    body = bandwidth_section(lt, out_html.parent)
    _page(f"swarmhil bandwidth: {lt.run}", body, out_html)
    return out_html


def fig_compare(a: LinkTraffic, b: LinkTraffic, path: Path) -> str:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4))
    for lt, style in ((a, "-"), (b, "--")):
        s = per_agent_series(lt, _bin_s(lt))
        x, xl = _time_axis(s["edges_s"][1:])
        axes[0].plot(x, np.cumsum(s["tx_bytes"].sum(0)), style, label=f"{lt.run}: sent")
        axes[0].plot(x, np.cumsum(s["rx_bytes"].sum(0)), style, label=f"{lt.run}: delivered")
        axes[0].set_xlabel(xl)
    axes[0].set_title("Cumulative bytes with overhead, whole swarm")
    axes[0].legend()
    ids = sorted(set(a.ids) | set(b.ids))
    x = np.arange(len(ids))
    for k, (lt, lab) in enumerate(((a, a.run), (b, b.run))):
        per = defaultdict(int)
        for _t, src, _d, _ty, n in lt.tx:
            per[src] += n + lt.overhead_bytes
        axes[1].bar(x + (k - 0.5) * 0.4, [per[i] for i in ids], width=0.4, label=lab)
    axes[1].set_xticks(x, ids, rotation=90, fontsize=7)
    axes[1].set_title("Bytes sent per spacecraft (with overhead)")
    axes[1].legend()
    return _save(fig, path)


def write_bandwidth_comparison(run_a: str | Path | LinkTraffic, run_b: str | Path | LinkTraffic,
                               out_html: str | Path) -> Path:
    """Two runs side by side: totals, ratios, per-spacecraft bytes, link matrices on one colour scale."""
    out_html = Path(out_html)
    out_dir = out_html.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    a, b = _load(run_a), _load(run_b)
    ta, tb = totals(a), totals(b)
    rows = []
    for k in ("tx_messages", "tx_payload_bytes", "tx_wire_bytes", "rx_messages", "rx_payload_bytes", "rx_wire_bytes",
              "rejected_packets"):
        va, vb = ta["mcap"][k], tb["mcap"][k]
        rows.append([k, va, vb, (vb / va) if va else None])
    for c in DROP_CAUSES:
        va = (ta["link_stats"] or {}).get(f"dropped_{c}")
        vb = (tb["link_stats"] or {}).get(f"dropped_{c}")
        rows.append([f"dropped_{c}", va, vb, (vb / va) if va else None])
    for lt, t in ((a, ta), (b, tb)):
        rows.append([f"mean bit/s per spacecraft ({lt.run})", None, None,
                     t["mcap"]["tx_wire_bytes"] * 8 / max(lt.t_end_s, 1e-9) / max(len(lt.ids), 1)])
    ok_a = all(c[-1] for c in consistency(a))
    ok_b = all(c[-1] for c in consistency(b))
    body = _table(["quantity", f"A: {a.run}", f"B: {b.run}", "B / A"], rows)
    body += f"<p>recording and channel counters agree: A {_ok(ok_a)}, B {_ok(ok_b)}</p>"
    vmax = max(link_matrix(a).max(initial=0.0), link_matrix(b).max(initial=0.0), 1.0)
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(14, 6.2))
    fig_matrix(a, None, vmax=vmax, ax=axes[0])
    fig_matrix(b, None, vmax=vmax, ax=axes[1])
    mname = _save(fig, out_dir / "bandwidth_compare_matrix.png")
    body += figure_html(static_figure(out_dir, fig_compare(a, b, out_dir / "bandwidth_compare.png"), "A solid, B dashed."))
    body += figure_html(static_figure(out_dir, mname, "Link matrices on one colour scale."))
    _page(f"swarmhil bandwidth: {a.run} vs {b.run}", body, out_html)
    return out_html
