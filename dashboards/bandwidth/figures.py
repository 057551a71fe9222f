"""The bandwidth figures (matplotlib PNGs, one Plotly spec) of a run and of two runs compared."""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.bandwidth.accounting import (
    bin_width_s,
    drops_by_transmitter,
    link_matrix,
    per_agent_series,
)
from swarmhil.dashboards.bandwidth.read import LinkTraffic
from swarmhil.dashboards.figstyle import Line, LineFigure, Panel, colors, integer_axis, legend
from swarmhil.dashboards.figstyle import pyplot as _plt
from swarmhil.dashboards.figstyle import save as _save
from swarmhil.dashboards.figstyle import time_axis as _time_axis
from swarmhil.link.model import DROP_CAUSES


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


def fig_compare(a: LinkTraffic, b: LinkTraffic, path: Path) -> str:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4))
    for lt, style in ((a, "-"), (b, "--")):
        s = per_agent_series(lt, bin_width_s(lt))
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

