"""The two accountings of a run's link traffic (the recording's samples and the channel's own
counters), their consistency, and the per-agent, per-link and per-cause series the figures draw."""
from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np

from swarmhil.dashboards.bandwidth.read import LinkTraffic
from swarmhil.link.model import DROP_CAUSES, TX_ROW

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


def bin_width_s(lt: LinkTraffic) -> float:
    dur = max(lt.t_end_s, lt.step_s)
    return max(lt.step_s, float(lt.config.get("stats_period_s", 60.0)) if dur <= 6 * 3600 else dur / 200.0)

