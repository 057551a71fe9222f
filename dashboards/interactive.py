"""Interactive figures of the report site (Plotly), for plots with many lines (issue 18).

The same `LineFigure` the static figure is drawn from (dashboards/figstyle.py) becomes a Plotly
figure: one trace per line with its name in a clickable legend (click hides a spacecraft, double
click isolates it), hover with the values, zoom. Pages load plotly.js from ONE file of the site
(`plotly.min.js`, written by `write_plotly_js` from the `plotly` package: offline, no CDN) and embed
only each figure's data. Lines longer than MAX_POINTS are decimated for the browser (every k-th
sample and the last); the static PNG/SVG/PDF keep every sample.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmhil.dashboards.figstyle import _DASH, LineFigure

PLOTLY_JS = "plotly.min.js"
MAX_POINTS = 1500


def write_plotly_js(out_dir: Path) -> str:
    """plotly.js (the version the `plotly` package ships) into out_dir once; its file name."""
    from plotly.offline import get_plotlyjs

    p = Path(out_dir) / PLOTLY_JS
    js = get_plotlyjs()
    if not p.is_file() or p.stat().st_size != len(js.encode()):
        p.write_text(js)
    return PLOTLY_JS


def _hex(c) -> str | None:  # type: ignore[no-untyped-def]
    if c is None:
        return None
    from matplotlib.colors import to_hex

    return to_hex(c)


def _decimate(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(x)
    if n <= MAX_POINTS:
        return x, y
    idx = np.unique(np.r_[np.arange(0, n, int(np.ceil(n / MAX_POINTS))), n - 1])
    return x[idx], y[idx]


def plotly_div(spec: LineFigure, div_id: str) -> str:
    """The figure as a <div> and its script (plotly.js loaded by the page)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    n = len(spec.panels)
    fig = make_subplots(rows=n, cols=1, shared_xaxes=spec.sharex, vertical_spacing=0.08 if n > 1 else 0.0,
                        subplot_titles=[p.title for p in spec.panels])
    named: set[str] = set()
    for r, p in enumerate(spec.panels, start=1):
        for ln in p.lines:
            x, y = _decimate(np.asarray(ln.x, float), np.asarray(ln.y, float))
            group = ln.name or None
            show = bool(ln.legend and ln.name and ln.name not in named)
            if show:
                named.add(ln.name)
            mode = "markers" if ln.marker else "lines"
            fig.add_trace(go.Scatter(
                x=x, y=y, name=ln.name, legendgroup=group, showlegend=show, mode=mode,
                line=dict(color=_hex(ln.color), width=max(ln.width * 1.4, 1.0), dash=_DASH.get(ln.dash, "solid"),
                          shape="hv" if ln.step else "linear")), row=r, col=1)
        for yv, c, lab in p.hlines:
            fig.add_hline(y=yv, line=dict(color=_hex(c), dash="dash", width=1), row=r, col=1,
                          annotation_text=lab or None, annotation_position="top left")
        if p.shade is not None:
            fig.add_vrect(x0=p.shade[0], x1=p.shade[1], fillcolor="#e5e5e5", opacity=0.6, line_width=0, layer="below",
                          row=r, col=1)
        fig.update_yaxes(title_text=p.ylabel, type="log" if p.log_y else None, row=r, col=1)
        if p.ylim is not None and not p.log_y:
            fig.update_yaxes(range=list(p.ylim), row=r, col=1)
        if p.integer_y:
            fig.update_yaxes(tickformat="d", dtick=1 if p.ylim is not None and (p.ylim[1] or 0) <= 12 else None,
                             row=r, col=1)
        if p.equal:
            fig.update_yaxes(scaleanchor=f"x{r if r > 1 else ''}", row=r, col=1)
        if p.xlabel:
            fig.update_xaxes(title_text=p.xlabel, row=r, col=1)
    fig.update_layout(title=dict(text=spec.title), height=int(150 + 300 * n), template="plotly_white",
                      legend=dict(font=dict(size=10), itemclick="toggle", itemdoubleclick="toggleothers"),
                      margin=dict(l=70, r=20, t=70, b=50))
    return fig.to_html(full_html=False, include_plotlyjs=False, div_id=div_id,
                       config={"displaylogo": False, "responsive": True})
