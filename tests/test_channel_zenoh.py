"""The link channel as its own process over real Zenoh, checked from the recording alone.

One `swarmhil run` (deploy.launcher.MultiProcessRun): 5 agent processes, the plant, the recorder
and the channel, 300 simulated seconds in lockstep, a beacon from every agent every step. The
checks read run.mcap with the standard `mcap` reader and the `mcap-protobuf-support` decoder only
(tests/conftest.py read_mcap), not the project's classes.
"""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from conftest import read_mcap

SCENARIO = """
[run]
name = "link-zenoh"
duration_s = 300.0
step_s = 10.0
seed = 11

[controller]
name = "null"

[dispersion]
count = 5
sigma_roe_m = [30.0, 40.0, 30.0, 30.0, 30.0, 30.0]
along_track_spacing_m = 200.0

[link]
range_m = {range_m}
loss_probability = {p}
overhead_bytes = 24
stats_period_s = 50.0

[beacon]
period_s = 10.0
"""
RANGE_M = 400.0
P_LOSS = 0.25


@pytest.fixture(scope="module")
def zenoh_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from deploy.launcher import MultiProcessRun
    from deploy.scenario import load_scenario

    d = tmp_path_factory.mktemp("linkzenoh")
    path = d / "link-zenoh.toml"
    path.write_text(SCENARIO.format(range_m=RANGE_M, p=P_LOSS))
    out = d / "out"
    res = MultiProcessRun(str(path), load_scenario(path), out, progress=False).execute()
    assert res.exit_code == 0, res.reason
    assert res.summary["steps"] == 30 and not res.summary["dead_agents"]
    return out


def _recording(out: Path) -> dict:
    msgs = read_mcap(out / "run.mcap")
    truth = {round(m.header.t, 6): {b.id: np.array([b.position_m.x, b.position_m.y, b.position_m.z]) for b in m.bodies}
             for t, _l, _p, m in msgs if t.endswith("/truth")}
    tx = [(t.rsplit("/", 1)[1], m) for t, _l, _p, m in msgs if "/isl/tx/" in t]
    rx = [(t.rsplit("/", 1)[1], m) for t, _l, _p, m in msgs if "/isl/rx/" in t]
    stats_msgs = [m for t, _l, _p, m in msgs if t.endswith("/link/stats")]
    config = [json.loads(m.detail) for t, _l, _p, m in msgs if t.endswith("/event") and m.kind == "link_config"]
    return {"truth": truth, "tx": tx, "rx": rx, "stats": stats_msgs, "config": config}


def test_no_delivery_beyond_range_and_binomial_loss(zenoh_run: Path) -> None:
    rec = _recording(zenoh_run)
    truth, tx, rx = rec["truth"], rec["tx"], rec["rx"]
    ids = sorted(next(iter(truth.values())))
    assert len(tx) == 5 * 30 and all(key == m.src for key, m in tx)
    # every delivery: a receiver within range of the sender at the time of sending
    delivered = Counter()
    for receiver, m in rx:
        pos = truth[round(m.sent_t, 6)]
        assert np.linalg.norm(pos[receiver] - pos[m.src]) <= RANGE_M
        assert m.header.t > m.sent_t  # delivered at a later step than it was sent
        delivered[(m.src, m.sent_t, receiver)] += 1  # one beacon per agent and step
    assert max(delivered.values()) == 1  # no duplicates
    # candidates: every (packet, other spacecraft) pair in range at the time of sending
    in_range = out_of_range = 0
    for _key, m in tx:
        pos = truth[round(m.sent_t, 6)]
        for r in ids:
            if r == m.src:
                continue
            if np.linalg.norm(pos[r] - pos[m.src]) <= RANGE_M:
                in_range += 1
            else:
                out_of_range += 1
                assert (m.src, m.sent_t, r) not in delivered
    assert in_range > 150 and out_of_range > 50  # the range really gates
    n_ok = len(rx)
    lo, hi = stats.binom.ppf([1e-4, 1 - 1e-4], in_range, 1 - P_LOSS)
    assert lo <= n_ok <= hi, (n_ok, in_range)


def test_report_totals_equal_the_recording_and_the_channel_counters(zenoh_run: Path) -> None:
    from dashboards.bandwidth import consistency, read_link_traffic, totals, write_bandwidth_report

    rec = _recording(zenoh_run)
    overhead = rec["config"][0]["overhead_bytes"]
    assert overhead == 24
    counted = {
        "tx_messages": len(rec["tx"]),
        "tx_payload_bytes": sum(len(m.payload) for _k, m in rec["tx"]),
        "tx_wire_bytes": sum(len(m.payload) + overhead for _k, m in rec["tx"]),
        "rx_messages": len(rec["rx"]),
        "rx_payload_bytes": sum(len(m.payload) for _k, m in rec["rx"]),
        "rx_wire_bytes": sum(len(m.payload) + overhead for _k, m in rec["rx"]),
    }
    last = rec["stats"][-1]
    from_stats = {
        "tx_messages": sum(c.messages for c in last.links if c.dst == "*"),
        "tx_payload_bytes": sum(c.payload_bytes for c in last.links if c.dst == "*"),
        "tx_wire_bytes": sum(c.wire_bytes for c in last.links if c.dst == "*"),
        "rx_messages": sum(c.messages for c in last.links if c.dst != "*"),
        "rx_payload_bytes": sum(c.payload_bytes for c in last.links if c.dst != "*"),
        "rx_wire_bytes": sum(c.wire_bytes for c in last.links if c.dst != "*"),
    }
    summary = json.loads((zenoh_run / "summary.json").read_text())["channel"]["totals"]
    report = totals(read_link_traffic(zenoh_run))["mcap"]
    for k, v in counted.items():
        assert report[k] == v == from_stats[k] == summary[k], k
    assert last.tx_messages == counted["tx_messages"] and last.rx_messages == counted["rx_messages"]
    # per link, too: deliveries per (src, receiver) in the recording = the channel's per-link counters
    per_link = Counter((m.src, r) for r, m in rec["rx"])
    assert per_link == Counter({(c.src, c.dst): c.messages for c in last.links if c.dst != "*" and c.messages})
    assert all(ok for *_x, ok in consistency(read_link_traffic(zenoh_run)))
    html = write_bandwidth_report(zenoh_run)
    assert html.is_file() and "Per link and message type" in html.read_text()
    for png in ("per_agent", "rate", "matrix", "drops"):
        assert (html.parent / f"bandwidth_{png}.png").stat().st_size > 5000
