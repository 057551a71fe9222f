"""The report site of a run (issue 18): RUN/report/ with one page per section, all from one Jinja2
template set (dashboards/templates/), linked from RUN/report/index.html by a bar on every page.

- index.html: the overview every run has (headline table: dV, closest approach, link traffic,
  events), then every registered mission section that applies (dashboards/sections/; paper 002's
  metrics and figures are its section p002.py), and the list of pages;
- navigation.html when agents reported navigation (tracks or decisions in their telemetry);
- bandwidth.html when the run had a link (isl or link/stats topics);
- events.html: the event log;
- data.html: the tables of data/ (Parquet and CSV, dashboards/frames.py).

Figures with many lines are interactive (Plotly; plotly.js is one file of the site, no CDN) with
their static PNG/SVG/PDF linked; the others are PNG images with their SVG/PDF linked. This module
only assembles pages: reading is dashboards/frames.py, analysis dashboards/metrics.py and
dashboards/navreport/, figures dashboards/figstyle.py and interactive.py, the page helpers the report kit
dashboards/kit.py.
"""
from __future__ import annotations

import html
from collections import Counter
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from swarmhil.bus.keys import split_topic
from swarmhil.dashboards.bandwidth.page import bandwidth_section
from swarmhil.dashboards.bandwidth.read import read_link_traffic
from swarmhil.dashboards.frames import metrics_frame, read_frames, write_tables
from swarmhil.dashboards.interactive import write_plotly_js
from swarmhil.dashboards.kit import SiteFigure, figures_of, nav_bar, render
from swarmhil.dashboards.navreport.analysis import analyse_run
from swarmhil.dashboards.navreport.figures import nav_figures
from swarmhil.dashboards.navreport.page import diagnosis_rows, nav_diagnosis, nav_table_rows

MAX_EVENT_ROWS = 5000  # rows of the event page; data/events.csv has them all


def traffic_rows(fr: dict[str, Any]) -> list[tuple[str, str]]:
    """The overview's link traffic and events of a run (frames of dashboards/frames.py): the
    channel's counters at its last LinkStats sample, summed as link/model.py `totals` does
    (transmitters' own rows "*" sent, the others delivered or dropped), and the events by kind."""
    link = fr["link"]
    if len(link):
        last = link[link["step"] == link["step"].max()]
        tx, rx = last[last["dst"] == "*"], last[last["dst"] != "*"]
        traffic = (f"{int(tx['messages'].sum())} messages sent ({int(tx['payload_bytes'].sum())} B payload), "
                   f"{int(rx['messages'].sum())} delivered; dropped: {int(rx['dropped_range'].sum())} out of range, "
                   f"{int(rx['dropped_occulted'].sum())} occulted, {int(rx['dropped_lost'].sum())} lost, "
                   f"{int(tx['dropped_queue'].sum())} at a full queue")
    else:
        traffic = "no link in this run"
    ev = fr["events"]
    counts = ", ".join(f"{html.escape(str(k))}: {n}" for k, n in sorted(Counter(ev["kind"]).items()))
    return [("link traffic", traffic), ("events", f"{len(ev)}" + (f" ({counts})" if counts else ""))]


def write_site(run_dir: Path, out: Path, title: str, head: list[tuple[str, str]], figures: list[SiteFigure],
               sections: list[dict[str, Any]], metrics_series: Any, metrics: dict[str, Any], intro: str = "") -> Path:
    """Every page of the site and data/ (module docstring). Returns index.html."""
    from markupsafe import Markup  # Jinja2's (the reports extra): imported where used, bus/optional.py

    fr = read_frames(run_dir / "run.mcap")
    tables = {k: fr[k] for k in ("truth", "commands", "link", "link_totals", "events")}
    tables["metrics_series"] = metrics_series
    tables["metrics"] = metrics_frame(metrics)
    written = write_tables(tables, out / "data")
    topics = _topics(run_dir / "run.mcap")
    has_link = any(t.startswith("isl/") or t == "link/stats" for t in topics)
    nav_body = _navigation(run_dir, out) if any(t.startswith("sc/") and t.endswith("/tm") for t in topics) else None
    available = {"index.html", "events.html", "data.html"} | ({"bandwidth.html"} if has_link else set()) | (
        {"navigation.html"} if nav_body is not None else set())
    bar = nav_bar(available)
    interactive = any(f.div for f in figures) or any(f.div for s in sections for f in s["figures"])
    js = write_plotly_js(out) if interactive or has_link else None
    notes = {"navigation.html": "navigation error of every track against truth",
             "bandwidth.html": "link traffic, drops, and the channel's counters checked against the recording",
             "events.html": f"{len(fr['events'])} events", "data.html": "time series and metrics as Parquet and CSV"}
    links = [{"href": p["href"], "label": p["label"], "note": notes.get(p["href"], "")} for p in bar[1:]]
    if has_link:
        lt = read_link_traffic(run_dir)
        render("page.html", out / "bandwidth.html", title=f"Bandwidth: {lt.run}", pages=bar,
               intro=bandwidth_section(lt, out, interactive=js is not None), plotly_js=js)
    if nav_body is not None:
        render("page.html", out / "navigation.html", title=f"Navigation error: {fr['run']}", pages=bar,
               head=nav_body[0], figures=nav_body[1], intro=nav_body[2], sections=nav_body[3])
    ev = fr["events"]
    render("events.html", out / "events.html", title=f"Events: {fr['run']}", pages=bar,
           events=[(f"{r.t_s:.6g}", r.step, r.source, r.kind, r.subject, r.detail)
                   for r in ev.head(MAX_EVENT_ROWS).itertuples()],
           total=len(ev), counts=sorted(Counter(ev["kind"]).items()))
    rows = [(t["name"], t["rows"], ", ".join(t["columns"]),
             Markup(f'<a href="data/{html.escape(t["name"])}.parquet">{html.escape(t["name"])}.parquet</a>'),
             Markup(f'<a href="data/{html.escape(t["name"])}.csv">{html.escape(t["name"])}.csv</a>')) for t in written]
    render("data.html", out / "data.html", title=f"Data tables: {fr['run']}", pages=bar, tables=rows,
           run_dir=str(run_dir))
    return render("page.html", out / "index.html", title=title, pages=bar, head=[*head, *traffic_rows(fr)],
                  figures=figures,
                  sections=sections, links=links, intro=Markup(intro), plotly_js=js)


def _topics(mcap: Path) -> set[str]:
    with open(mcap, "rb") as f:
        s = make_reader(f).get_summary()
    return {split_topic(ch.topic)[1] for ch in s.channels.values()} if s is not None else set()


def _navigation(run_dir: Path, out: Path) -> tuple[list[tuple[str, str]], list[SiteFigure], str, list[dict[str, Any]]] | None:
    """(head rows, figures, note, sections: the splits and the per-step comparison) of the navigation
    page; None when no agent reported navigation."""
    nav = analyse_run(run_dir)
    if nav.rows.n == 0 and nav.decisions.step.size == 0:
        return None
    figs = figures_of(out, nav_figures(nav, out, prefix="nav_"))
    _sps, _steps, sections = nav_diagnosis(nav, out, prefix="nav_")
    head = [(k, html.escape(v)) for k, v in nav_table_rows(nav.summary) + diagnosis_rows(nav.summary)]
    return head, figs, "<p>Definitions: dashboards/navreport/ (package docstring).</p>", sections
