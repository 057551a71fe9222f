"""The report kit: what every report page is made of, at the ground of dashboards/ (issue 25).

- pages: the Jinja2 templates of dashboards/templates/ (`render`), the link bar (`PAGES`,
  `nav_bar`, `bar_for`), figures as the pages show them (`SiteFigure`: a PNG with its static copies,
  or a Plotly figure; `static_figure`, `line_figure`, `figures_of`, `figure_html`);
- table cells: `fmt`, `pct`, `check`, `approach`, `head_table`.

Figure style is dashboards/figstyle.py (static) and dashboards/interactive.py (Plotly), below this
module. It imports nothing else of dashboards, so every report module (the run report and its site,
the mission sections, navigation, bandwidth) imports it without a circle.
"""
from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarmhil.dashboards import figstyle
from swarmhil.dashboards.figstyle import LineFigure, render_static, span_text
from swarmhil.dashboards.interactive import plotly_div

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
        f.div = plotly_div(spec, f"plot-{f.stem}")
    return f


def figures_of(out: Path, pairs: list[Any]) -> list[SiteFigure]:
    """(PNG name, caption) pairs of the mission sections and navreport as SiteFigures; a SiteFigure
    (a section's interactive figure) is kept as it is."""
    return [f if isinstance(f, SiteFigure) else static_figure(out, *f) for f in pairs
            if isinstance(f, SiteFigure) or f[0]]


def figure_html(f: SiteFigure) -> str:
    """One figure as the pages show it (the `figure` macro of templates/macros.html)."""
    return str(_env().get_template("macros.html").module.figure(f))


def nav_bar(available: set[str]) -> list[dict[str, str]]:
    return [{"href": h, "label": lab} for h, lab in PAGES if h in available]


def bar_for(page: Path) -> list[dict[str, str]] | None:
    """The link bar for a page written on its own (report-bandwidth) into an existing site, else None."""
    d = page.parent
    if page.name not in dict(PAGES) or not (d / "index.html").is_file():
        return None
    return nav_bar({h for h, _l in PAGES if (d / h).is_file()} | {page.name})


# --- table cells ---------------------------------------------------------------------------------------


def fmt(v: Any, digits: int = 3) -> str:
    """One value as a table cell: None n/a, booleans yes/no, floats to `digits` significant digits
    (integers from 1e4 up), anything else escaped text."""
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f"{v:.{digits}g}" if abs(v) < 1e4 else f"{v:.0f}"
    return html.escape(str(v))


def pct(x: float | None) -> str:
    """A fraction as a percentage with one decimal (None: n/a)."""
    return "n/a" if x is None else f"{100.0 * x:.1f} %"


def check(ok: bool) -> str:
    """A yes/no cell coloured by the page's style (classes ok/bad of templates/base.html)."""
    return '<span class="ok">yes</span>' if ok else '<span class="bad">no</span>'


def head_table(rows: list[tuple[str, str]]) -> str:
    """(name, cell HTML) rows as the two-column table of a page's head (templates/macros.html
    head_table); names are escaped as Jinja2 escapes them, cells are HTML already."""
    return "<table>" + "".join(f"<tr><th>{html.escape(k).replace('&#x27;', '&#39;')}</th><td>{v}</td></tr>"
                               for k, v in rows) + "</table>"


def approach(d: dict[str, Any]) -> str:
    """A closest approach of dashboards/metrics.py ({distance_m, pair, t_s}) as a cell."""
    if d["distance_m"] is None:
        return "none"
    return f"{fmt(d['distance_m'])} m ({'-'.join(d['pair'])} at t = {span_text(d['t_s'])})"
