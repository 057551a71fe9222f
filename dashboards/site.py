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
navreport.py, figures dashboards/figstyle.py and interactive.py.
"""
from __future__ import annotations

import html
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dashboards import figstyle
from dashboards.figstyle import LineFigure, render_static

MAX_EVENT_ROWS = 5000  # rows of the event page; data/events.csv has them all
PAGES = [("index.html", "Overview and mission metrics"), ("navigation.html", "Navigation"),
         ("bandwidth.html", "Bandwidth"), ("events.html", "Events"), ("data.html", "Data tables")]


@dataclass
class SiteFigure:
    stem: str
    src: str                                   # the PNG
    caption: str                               # HTML
    div: str | None = None                     # the Plotly figure, when interactive
    exports: list[tuple[str, str]] = field(default_factory=list)  # (format, file) of the static copies


def _env():  # type: ignore[no-untyped-def]
    from jinja2 import Environment, PackageLoader, select_autoescape

    return Environment(loader=PackageLoader("dashboards", "templates"), autoescape=select_autoescape(["html"]),
                       trim_blocks=True, lstrip_blocks=True)


def render(template: str, out: Path, **ctx: Any) -> Path:
    """Render a template of dashboards/templates to out (ctx: title, pages, here, ...)."""
    ctx.setdefault("pages", None)
    ctx.setdefault("here", out.name)
    out.write_text(_env().get_template(template).render(**ctx))
    return out


def static_figure(out: Path, png: str, caption: str) -> SiteFigure:
    """An image already written into out, with the static copies that exist beside it."""
    stem = Path(png).stem
    ex = [("PNG", png)] + [(e.upper(), f"{stem}.{e}") for e in figstyle.EXPORT if (out / f"{stem}.{e}").is_file()]
    return SiteFigure(stem, png, caption, None, ex)


def line_figure(out: Path, spec: LineFigure, png: str, caption: str, interactive: bool = True) -> SiteFigure:
    """A LineFigure drawn static (PNG + exports) and, when interactive, as a Plotly div."""
    render_static(spec, out / png)
    f = static_figure(out, png, caption)
    if interactive:
        from dashboards.interactive import plotly_div

        f.div = plotly_div(spec, f"plot-{f.stem}")
    return f


def figures_of(out: Path, pairs: list[Any]) -> list[SiteFigure]:
    """(PNG name, caption) pairs of the mission sections and navreport as SiteFigures; a SiteFigure
    (a section's interactive figure) is kept as it is."""
    return [f if isinstance(f, SiteFigure) else static_figure(out, *f) for f in pairs
            if isinstance(f, SiteFigure) or f[0]]


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


def figure_html(f: SiteFigure) -> str:
    """One figure as the pages show it (the `figure` macro of templates/macros.html)."""
    return str(_env().get_template("macros.html").module.figure(f))


def _nav_bar(available: set[str]) -> list[dict[str, str]]:
    return [{"href": h, "label": lab} for h, lab in PAGES if h in available]


def bar_for(page: Path) -> list[dict[str, str]] | None:
    """The link bar for a page written on its own (report-bandwidth) into an existing site, else None."""
    d = page.parent
    if page.name not in dict(PAGES) or not (d / "index.html").is_file():
        return None
    return _nav_bar({h for h, _l in PAGES if (d / h).is_file()} | {page.name})


def write_site(run_dir: Path, out: Path, title: str, head: list[tuple[str, str]], figures: list[SiteFigure],
               sections: list[dict[str, Any]], metrics_series: Any, metrics: dict[str, Any], intro: str = "") -> Path:
    """Every page of the site and data/ (module docstring). Returns index.html."""
    from markupsafe import Markup

    from dashboards.frames import metrics_frame, read_frames, write_tables
    from dashboards.interactive import write_plotly_js

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
    bar = _nav_bar(available)
    interactive = any(f.div for f in figures) or any(f.div for s in sections for f in s["figures"])
    js = write_plotly_js(out) if interactive or has_link else None
    notes = {"navigation.html": "navigation error of every track against truth",
             "bandwidth.html": "link traffic, drops, and the channel's counters checked against the recording",
             "events.html": f"{len(fr['events'])} events", "data.html": "time series and metrics as Parquet and CSV"}
    links = [{"href": p["href"], "label": p["label"], "note": notes.get(p["href"], "")} for p in bar[1:]]
    if has_link:
        from dashboards.bandwidth import bandwidth_section, read_link_traffic

        lt = read_link_traffic(run_dir)
        render("page.html", out / "bandwidth.html", title=f"Bandwidth: {lt.run}", pages=bar,
               intro=bandwidth_section(lt, out, interactive=js is not None), plotly_js=js)
    if nav_body is not None:
        render("page.html", out / "navigation.html", title=f"Navigation error: {fr['run']}", pages=bar,
               head=nav_body[0], figures=nav_body[1], intro=nav_body[2])
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
    from mcap.reader import make_reader

    from bus.keys import split_topic

    with open(mcap, "rb") as f:
        s = make_reader(f).get_summary()
    return {split_topic(ch.topic)[1] for ch in s.channels.values()} if s is not None else set()


def _navigation(run_dir: Path, out: Path) -> tuple[list[tuple[str, str]], list[SiteFigure], str] | None:
    """(head rows, figures, note) of the navigation page; None when no agent reported navigation."""
    from dashboards.navreport import analyse_run, nav_figures, nav_table_rows

    nav = analyse_run(run_dir)
    if nav.rows.n == 0 and nav.decisions.step.size == 0:
        return None
    figs = figures_of(out, nav_figures(nav, out, prefix="nav_"))
    return [(k, html.escape(v)) for k, v in nav_table_rows(nav.summary)], figs, "<p>Definitions: dashboards/navreport.py.</p>"
