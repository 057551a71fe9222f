"""Static figures of every report (matplotlib): one style, one save, windows and time axes from the run.

- `pyplot()`: Agg backend, 150 dpi (issue 18: the reports were 100 dpi), grid, small fonts.
- `save(fig, path)`: PNG for the HTML page, and the vector copies for papers (`EXPORT`: SVG with its
  text kept as text, PDF) beside it, same stem. The bounding box is the drawn content
  (`bbox_inches="tight"`), so no title or label is cut at the figure's edge.
- `time_axis(t_s)`: hours for runs of 3 h and more, else minutes (a 20-min run on a "time [h]"
  axis reads 0-0.33).
- `span_text(s)` / `window_text(run_s, want_s)`: a duration as a person writes it, and the label
  of a trailing window clipped to the run ("last 1 h", or "whole run, 20 min" when the run is
  shorter than the window).
- `integer_axis(axis)`: whole-number ticks for counts (components, spacecraft, drops).
- `legend(ax, n)`: a legend for per-spacecraft lines, compact and outside the axes when there are many.
"""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

DPI = 150
EXPORT: tuple[str, ...] = ("svg", "pdf")  # vector copies written beside every PNG (set () to skip)
H = 3600.0


def pyplot():
    matplotlib = require("matplotlib", "the report's figures")

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"figure.dpi": DPI, "savefig.dpi": DPI, "axes.grid": True, "grid.alpha": 0.3,
                         "font.size": 9, "legend.fontsize": 7, "svg.fonttype": "none",
                         "path.simplify": True, "agg.path.chunksize": 20000})
    return plt


@contextmanager
def exporting(formats: tuple[str, ...]) -> Iterator[None]:
    """Within the block, save() writes these vector copies (e.g. () for PNG only)."""
    global EXPORT
    old, EXPORT = EXPORT, tuple(formats)
    try:
        yield
    finally:
        EXPORT = old


def colors(n: int) -> list:
    cmap = pyplot().get_cmap("tab20")
    return [cmap(i % 20) for i in range(n)]


def save(fig: Any, path: Path, export: tuple[str, ...] | None = None) -> str:
    """Write fig as path (PNG) and as each of `export` (default EXPORT) with the same stem; close it."""
    path = Path(path)
    box = fig.get_tightbbox(fig.canvas.get_renderer()).padded(0.08)  # inches; computed once for every format
    fig.savefig(path, bbox_inches=box)
    for ext in (EXPORT if export is None else export):
        fig.savefig(path.with_suffix(f".{ext}"), bbox_inches=box)
    pyplot().close(fig)
    return path.name


def time_unit(t_s: np.ndarray) -> tuple[float, str]:
    """(seconds per display unit, axis label): hours for runs of 3 h and more, minutes below."""
    t_s = np.asarray(t_s, dtype=float)
    fin = t_s[np.isfinite(t_s)]
    span = float(fin.max() - fin.min()) if fin.size else 0.0
    return (H, "time [h]") if span >= 3 * H else (60.0, "time [min]")


def time_axis(t_s: np.ndarray) -> tuple[np.ndarray, str]:
    """(t in display units, axis label), units by time_unit."""
    div, label = time_unit(t_s)
    return np.asarray(t_s, dtype=float) / div, label


def span_text(s: float) -> str:
    """'45 s', '20 min', '4.7 h', '1 d 2 h'."""
    if s < 120:
        return f"{s:.3g} s"
    if s < H:
        return f"{s / 60:.3g} min"
    if s < 48 * H:
        return f"{s / H:.3g} h"
    return f"{s / 86400:.3g} d"


def window_text(run_s: float, want_s: float | None) -> tuple[float, str]:
    """(window actually used [s], its label) for a trailing window of want_s on a run of run_s."""
    if want_s is None or want_s >= run_s:
        return run_s, f"whole run, {span_text(run_s)}"
    return want_s, f"last {span_text(want_s)}"


def integer_axis(axis: Any) -> None:
    """Whole-number ticks only (counts)."""
    from matplotlib.ticker import MaxNLocator

    axis.set_major_locator(MaxNLocator(integer=True))


def legend(ax: Any, n: int, **kw: Any) -> None:
    """Legend of n per-spacecraft lines: inside up to 6, else outside on the right in columns of 20."""
    if n <= 6:
        ax.legend(loc=kw.pop("loc", "best"), **kw)
    else:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), ncol=max(1, (n + 19) // 20), fontsize=6,
                  handlelength=1.2, borderaxespad=0.0, frameon=False, **kw)


def overflowing_texts(fig: Any) -> list[str]:
    """Titles and labels of fig drawn outside the figure or over another title: what a reader cannot
    read. Empty for a well laid-out figure (the tests check report figures with it)."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    fb = fig.bbox
    out, boxes = [], []
    texts = [t for a in fig.axes for t in (a.title, a._left_title, a._right_title, a.xaxis.label, a.yaxis.label)]
    if fig._suptitle is not None:
        texts.append(fig._suptitle)
    for t in texts:
        if not t.get_text() or not t.get_visible():
            continue
        b = t.get_window_extent(r)
        if b.x0 < fb.x0 - 1 or b.x1 > fb.x1 + 1 or b.y0 < fb.y0 - 1 or b.y1 > fb.y1 + 1:
            out.append(f"outside the figure: {t.get_text()!r}")
        for other, ob in boxes:
            if b.overlaps(ob):
                out.append(f"overlaps {other!r}: {t.get_text()!r}")
        boxes.append((t.get_text(), b))
    return out


# --- line figures drawn both statically (here) and interactively (dashboards/interactive.py) ---------
from dataclasses import dataclass, field  # noqa: E402

from swarmhil.bus.optional import require


@dataclass
class Line:
    x: np.ndarray
    y: np.ndarray
    name: str = ""
    color: Any = None          # a matplotlib colour (tuple or "C0"/"k"/"r"); None: the panel's cycle
    width: float = 0.8
    dash: str = "-"            # "-", "--", ":"
    step: bool = False         # drawn as steps (where="post")
    marker: bool = False       # markers only
    legend: bool = True        # this line is a legend entry


@dataclass
class Panel:
    lines: list[Line]
    ylabel: str
    title: str = ""
    hlines: list[tuple[float, str, str]] = field(default_factory=list)  # (y, colour, label)
    ylim: tuple[float | None, float | None] | None = None
    integer_y: bool = False
    log_y: bool = False
    shade: tuple[float, float] | None = None   # grey x span (the steady window)
    xlabel: str = ""
    equal: bool = False


@dataclass
class LineFigure:
    panels: list[Panel]
    title: str = ""
    width_in: float = 8.0
    panel_height_in: float = 3.0
    sharex: bool = True

    @property
    def n_lines(self) -> int:
        return max((sum(1 for ln in p.lines if ln.legend and ln.name) for p in self.panels), default=0)


_DASH = {"-": "solid", "--": "dash", ":": "dot"}


def render_static(spec: LineFigure, path: Path) -> str:
    """The LineFigure as a matplotlib figure saved to path (PNG and the EXPORT copies)."""
    return save(draw_static(spec), path)


def draw_static(spec: LineFigure):  # type: ignore[no-untyped-def]
    """The LineFigure as a matplotlib figure (not saved)."""
    plt = pyplot()
    n = len(spec.panels)
    fig, axs = plt.subplots(n, 1, figsize=(spec.width_in, spec.panel_height_in * n + 0.5), sharex=spec.sharex,
                            squeeze=False)
    for ax, p in zip(axs[:, 0], spec.panels):
        for ln in p.lines:
            kw = dict(color=ln.color, lw=ln.width, ls=ln.dash, label=ln.name if ln.legend and ln.name else None)
            if ln.marker:
                ax.plot(ln.x, ln.y, "o", color=ln.color, ms=3, label=kw["label"])
            elif ln.step:
                ax.step(ln.x, ln.y, where="post", **kw)
            else:
                ax.plot(ln.x, ln.y, **kw)
        for y, c, lab in p.hlines:
            ax.axhline(y, color=c, ls="--", lw=1.0, label=lab or None)
        if p.shade is not None:
            ax.axvspan(p.shade[0], p.shade[1], color="0.9", zorder=0)
        if p.log_y:
            ax.set_yscale("log")
        if p.ylim is not None:
            ax.set_ylim(*p.ylim)
        if p.integer_y:
            integer_axis(ax.yaxis)
        if p.equal:
            ax.set_aspect("equal", adjustable="datalim")
        ax.set_ylabel(p.ylabel)
        if p.xlabel:
            ax.set_xlabel(p.xlabel)
        if p.title:
            ax.set_title(p.title)
        if any(ln.legend and ln.name for ln in p.lines) or any(lab for _y, _c, lab in p.hlines):
            legend(ax, sum(1 for ln in p.lines if ln.legend and ln.name) + sum(1 for h in p.hlines if h[2]))
    if spec.title:
        fig.suptitle(spec.title)
    fig.tight_layout()
    return fig
