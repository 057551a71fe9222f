"""The bandwidth pages: the report section of one run, its own page, and two runs side by side."""
from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from swarmhil.dashboards.bandwidth.accounting import bin_width_s, consistency, link_matrix, totals
from swarmhil.dashboards.bandwidth.figures import (
    fig_compare,
    fig_drops,
    fig_matrix,
    fig_per_agent,
    fig_rate,
    spec_per_agent,
)
from swarmhil.dashboards.bandwidth.read import LinkTraffic, traffic_of, read_link_traffic
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.interactive import plotly_div
from swarmhil.dashboards.kit import bar_for, figure_html, render, static_figure
from swarmhil.link.model import COUNTER_FIELDS, DROP_CAUSES, TX_ROW


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


def write_page(title: str, body: str, out: Path) -> Path:
    """The page, with the report site's link bar when it joins a site (RUN/report/bandwidth.html)."""
    return render("page.html", out, title=title, intro=body, pages=bar_for(out))


def per_link_table(lt: LinkTraffic) -> list[list[Any]]:
    """Rows (src, dst, type, messages, payload bytes, wire bytes, drops by cause) of the channel's
    counters, dst "*" being the transmitter's own row (offered, queue drops)."""
    return [[s, d, t, *v] for (s, d, t), v in sorted(lt.stats_rows.items())]


def bandwidth_section(lt: LinkTraffic, out_dir: Path, prefix: str = "bandwidth_", interactive: bool = False) -> str:
    """The report's HTML body (figures written into out_dir): usable as a section of the main report.
    With `interactive`, the per-agent traffic is a Plotly figure (the page must load plotly.js)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    tot = totals(lt)
    bin_s = bin_width_s(lt)
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


def write_bandwidth_report(run_dir: str | Path, out_html: str | Path | None = None, *,
                           traffic: LinkTraffic | None = None) -> Path:
    """Bandwidth report of one run (default run_dir/report/bandwidth.html, PNGs beside it).

    `traffic`: the run's LinkTraffic when already read (read_link_traffic), to read the MCAP once."""
    run_dir = Path(run_dir)
    out_html = Path(out_html) if out_html else run_dir / "report" / "bandwidth.html"
    out_html.parent.mkdir(parents=True, exist_ok=True)
    lt = traffic or read_link_traffic(run_dir)
    body = bandwidth_section(lt, out_html.parent)
    write_page(f"swarmhil bandwidth: {lt.run}", body, out_html)
    return out_html


def write_bandwidth_comparison(run_a: str | Path | LinkTraffic, run_b: str | Path | LinkTraffic,
                               out_html: str | Path) -> Path:
    """Two runs side by side: totals, ratios, per-spacecraft bytes, link matrices on one colour scale."""
    out_html = Path(out_html)
    out_dir = out_html.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    a, b = traffic_of(run_a), traffic_of(run_b)
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
    write_page(f"swarmhil bandwidth: {a.run} vs {b.run}", body, out_html)
    return out_html

