"""The report kit: what every report page is made of, at the ground of dashboards/ (issue 25).

Table cells (`fmt`, `pct`, `check`, `head_table`) for now; the page helpers join it in the next step.
It imports nothing of dashboards but dashboards/figstyle.py, so every report module (the run report,
the mission sections, navigation, bandwidth) may import it without a circle.
"""
from __future__ import annotations

import html
import math
from typing import Any

from dashboards.figstyle import span_text


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
