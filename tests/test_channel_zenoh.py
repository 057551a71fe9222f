"""The link channel as its own process over real Zenoh, checked from the recording alone.

`swarmhil run`s (deploy.launcher.MultiProcessRun): 5 agent processes, the plant, the recorder
and the channel, 300 simulated seconds in lockstep, a beacon from every agent every step. The
checks read run.mcap with the standard `mcap` reader and the `mcap-protobuf-support` decoder only
(tests/conftest.py read_mcap), not the project's classes.

Issue 10: the same scenario with loss off, once undisturbed and once with the races forced on
purpose (bus/faults.py): the channel sees every clock tick 80 ms late, so every packet and command
reaches it before the tick of its step (early), and agent sc03's transmissions leave 400 ms after
its command (late: the channel must wait for the packets the command announces). Both runs must
give the same deliveries at the same steps, each dated by its send step and range-checked against
the truth of that step, with no deadline missed.
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


LATE_AGENT = "sc03"  # its packets leave 0.4 s after its command
RACES = {"channel": {"delay_rx": {"/clock": 0.08}}, f"agent-{LATE_AGENT}": {"delay_tx": {"/isl/tx/": 0.4}}}


def _run(tmp_path_factory: pytest.TempPathFactory, name: str, p_loss: float, faults: dict | None = None) -> Path:
    from swarmhil.deploy.launcher import MultiProcessRun
    from swarmhil.deploy.scenario import load_scenario

    d = tmp_path_factory.mktemp(name)
    path = d / "link-zenoh.toml"
    path.write_text(SCENARIO.format(range_m=RANGE_M, p=p_loss))
    out = d / "out"
    mp = pytest.MonkeyPatch()
    if faults:
        mp.setenv("SWARMHIL_FAULTS", json.dumps(faults))
    try:
        res = MultiProcessRun(str(path), load_scenario(path), out, progress=False).execute()
    finally:
        mp.undo()
    assert res.exit_code == 0, res.reason
    s = res.summary
    assert s["steps"] == 30 and not s["dead_agents"]
    # no lockstep deadline was missed: every window closed on its barrier, none on wall time
    assert not s["missed_deadlines"] and s["late_commands"] == 0, (s["missed_deadlines"], s["late_commands"])
    ch = json.loads((out / "summary.json").read_text())["channel"]
    assert ch["forced_windows"] == 0 and ch.get("stalls", 0) == 0 and ch["windows"] == 30, ch
    events = [m for t, _l, _p, m in read_mcap(out / "run.mcap") if t == "event"]
    assert not [e for e in events if e.kind in ("deadline_missed", "link_stall", "rejected_packet")]
    return out


@pytest.fixture(scope="module")
def zenoh_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run(tmp_path_factory, "linkzenoh", P_LOSS)


def _recording(out: Path) -> dict:
    msgs = read_mcap(out / "run.mcap")
    truth = {round(m.header.t, 6): {b.id: np.array([b.position_m.x, b.position_m.y, b.position_m.z]) for b in m.bodies}
             for t, _l, _p, m in msgs if t == "truth"}
    tx = [(t.rsplit("/", 1)[1], m) for t, _l, _p, m in msgs if t.startswith("isl/tx/")]
    rx = [(t.rsplit("/", 1)[1], m) for t, _l, _p, m in msgs if t.startswith("isl/rx/")]
    stats_msgs = [m for t, _l, _p, m in msgs if t == "link/stats"]
    config = [json.loads(m.detail) for t, _l, _p, m in msgs if t == "event" and m.kind == "link_config"]
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
    from swarmhil.dashboards.bandwidth.accounting import consistency, totals
    from swarmhil.dashboards.bandwidth.page import write_bandwidth_report
    from swarmhil.dashboards.bandwidth.read import read_link_traffic

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


def _deliveries(out: Path) -> dict[tuple[str, float, str], tuple[int, bytes]]:
    """(sender, send time, receiver) -> (receiver step, payload); asserts no duplicate."""
    got: dict[tuple[str, float, str], tuple[int, bytes]] = {}
    for receiver, m in _recording(out)["rx"]:
        key = (m.src, round(m.sent_t, 6), receiver)
        assert key not in got, f"delivered twice: {key}"
        got[key] = (int(m.header.step), bytes(m.payload))
    return got


def _check_dating(out: Path) -> dict[tuple[str, float, str], tuple[int, bytes]]:
    """Every in-range (packet, receiver) pair delivered once (loss off), none beyond range, each
    after its send step; the truth looked up is the one of the packet's own send step."""
    rec = _recording(out)
    truth, tx = rec["truth"], rec["tx"]
    got = _deliveries(out)
    want = set()
    for _key, m in tx:
        assert round(m.sent_t, 6) == round(10.0 * m.header.step, 6)  # an agent's sent_t is its step's time
        pos = truth[round(m.sent_t, 6)]
        for r in pos:
            if r != m.src and np.linalg.norm(pos[r] - pos[m.src]) <= RANGE_M:
                want.add((m.src, round(m.sent_t, 6), r))
    assert set(got) == want  # every packet delivered exactly when in range of its send-step truth (loss is off)
    assert len(want) > 150
    for (_src, sent_t, _r), (rx_step, _p) in got.items():
        assert rx_step * 10.0 > sent_t
    return got


@pytest.fixture(scope="module")
def clean_and_raced(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return _run(tmp_path_factory, "clean", 0.0), _run(tmp_path_factory, "raced", 0.0, RACES)


def test_undisturbed_run_delivers_every_in_range_packet_one_step_later(clean_and_raced: tuple[Path, Path]) -> None:
    clean, _ = clean_and_raced
    got = _check_dating(clean)
    assert all(rx_step * 10.0 == sent_t + 10.0 for (_s, sent_t, _r), (rx_step, _p) in got.items())
    ch = json.loads((clean / "summary.json").read_text())["channel"]
    assert ch["pending_at_end"] == {"queued": 0, "unevaluated": 0, "scheduled_deliveries": 0}


def test_early_and_late_packets_give_the_deliveries_of_the_undisturbed_run(clean_and_raced: tuple[Path, Path]) -> None:
    clean, raced = clean_and_raced
    ch = json.loads((raced / "summary.json").read_text())["channel"]
    # the races really happened: packets and commands ahead of their tick, sc03's packets after its command
    assert ch["early_packets"] > 50 and ch["early_commands"] > 50 and ch["waited_for_packets"] > 20, ch
    assert ch["late_packets"] == 0 and ch["pending_at_end"] == {"queued": 0, "unevaluated": 0, "scheduled_deliveries": 0}
    a, b = _check_dating(clean), _check_dating(raced)
    assert a == b  # same (sender, send time, receiver) -> (receiver step, payload)
