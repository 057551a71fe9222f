"""Every packet of a batch run (deploy/batch_packets.py): a batch `--record all` run records the
messages of the per-agent in-process run, byte for byte, topic by topic, in the same order and at
the same log times.

The one field that cannot agree is `Telemetry.compute_s` (wall time the flight software spent: a
measurement of each run); the comparison sets it to 0 in both after checking that each message is
protobuf's own serialisation of itself (so the bytes around it are compared as they are)."""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pytest

from conftest import SCENARIOS
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario


def _messages(path: Path, indexed: bool = False) -> list[tuple[str, int, int, bytes]]:
    """Every message in file order (`indexed`: in log time order, through the chunk and message
    indexes): (topic, sequence, log_time, data), read with the standard reader."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(ch.topic, m.sequence, m.log_time, m.data)
                for _s, ch, m in make_reader(f).iter_messages(log_time_order=indexed)]


def _without_compute_time(topic: str, data: bytes) -> bytes:
    if not topic.endswith("/tm"):
        return data
    tm = pb.Telemetry.FromString(data)
    assert tm.SerializeToString() == data  # (the bytes are protobuf's own: only compute_s is changed below)
    tm.compute_s = 0.0
    return tm.SerializeToString()


def assert_same_packets(per_agent: Path, batch: Path) -> dict[str, int]:
    """The two recordings hold the same messages: per topic the same count, log times and bytes
    (compute_s aside), and the same order of topics and sequence numbers in the file. Returns the
    message count per topic."""
    a, b = _messages(per_agent), _messages(batch)
    assert [(t, s, lt) for t, s, lt, _ in a] == [(t, s, lt) for t, s, lt, _ in b]
    ia, ib = _messages(per_agent, indexed=True), _messages(batch, indexed=True)  # (the indexes: every message once)
    assert sorted(ia) == sorted(a) and sorted(ib) == sorted(b)
    assert [(t, s, lt) for t, s, lt, _ in ia] == [(t, s, lt) for t, s, lt, _ in ib]
    by_topic: dict[str, int] = defaultdict(int)
    for (topic, seq, _lt, da), (_t, _s, _l, db) in zip(a, b):
        assert _without_compute_time(topic, da) == _without_compute_time(topic, db), (topic, seq)
        by_topic[topic] += 1
    return dict(by_topic)


def test_batch_packets_are_the_per_agent_packets(tmp_path: Path) -> None:
    sc = load_scenario(SCENARIOS / "sabatini-20.toml").with_overrides(duration_s=600.0)
    per_agent = run_in_process(sc, tmp_path / "agents", "same", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "batch", "same")
    assert per_agent.summary["batch"]["used"] is False and batch.summary["batch"] == {"used": True, "why_not": None}
    n = assert_same_packets(tmp_path / "agents" / "run.mcap", tmp_path / "batch" / "run.mcap")
    assert n["truth"] == n["clock"] == n["foxglove/scene"] == n["foxglove/tf"] == 61
    for sid in sc.ids:
        assert n[f"sc/{sid}/sense/rel"] == n[f"sc/{sid}/act"] == n[f"sc/{sid}/tm"] == 60
    assert batch.summary["recording"] == per_agent.summary["recording"]
    assert batch.summary["delta_v_total_mps"] == per_agent.summary["delta_v_total_mps"] > 0.0
    # the swarm's neighbour lists vary in length, and some telemetry carries decisions
    stims = [pb.RelStimulus.FromString(d) for t, _s, _l, d in _messages(tmp_path / "batch" / "run.mcap")
             if t.endswith("/sense/rel")]
    assert len({len(s.neighbours) for s in stims}) >= 3


def test_why_not_batch_names_what_only_the_per_agent_path_records() -> None:
    from swarmhil.deploy.batch import why_not_batch

    cam = load_scenario(SCENARIOS / "sabatini-20-camera-filter.toml")
    assert why_not_batch(cam) is None
    assert why_not_batch(cam, record="all") == "every packet of sensing kind 'scene' is recorded by the per-agent path"
    for name in ("sabatini-20", "tersoff-6", "surround-6", "servicing-6"):
        assert why_not_batch(load_scenario(SCENARIOS / f"{name}.toml"), record="all") is None, name


@pytest.mark.parametrize("record", ["all", "truth"])
def test_opts_batch_false_runs_the_agents(tmp_path: Path, record: str) -> None:
    sc = load_scenario(SCENARIOS / "sabatini-20.toml").with_overrides(duration_s=20.0)
    res = run_in_process(sc, tmp_path / record, "off", opts={"batch": False}, record=record)
    assert res.summary["batch"] == {"used": False, "why_not": "batch mode off (opts batch = false)"}


def test_dead_and_paused_agents_packets_are_the_per_agent_packets(tmp_path: Path) -> None:
    """Six spacecraft: sc03's flight software crashes at 50 s, sc04's is paused over [100, 150) s:
    the batch run writes no packet of theirs while they are out, and their sequence numbers go on
    from where they stopped, as the per-agent run's."""
    from conftest import six_with_process_faults
    from swarmhil.deploy.scenario import parse_scenario

    sc = parse_scenario(six_with_process_faults(), "six.toml")
    run_in_process(sc, tmp_path / "agents", "out", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "batch", "out")
    assert batch.summary["batch"]["used"]
    n = assert_same_packets(tmp_path / "agents" / "run.mcap", tmp_path / "batch" / "run.mcap")
    assert n["sc/sc03/act"] == 5 and n["sc/sc04/act"] == 15 and n["sc/sc05/act"] == 20


@pytest.mark.parametrize("sets", [(), ("sensing.params.position_noise_m=0.01",)], ids=["ideal", "noisy"])
def test_tersoff_packets_are_the_per_agent_packets(tmp_path: Path, sets: tuple[str, ...]) -> None:
    """Paper 001 (tersoff-6, the `relative` kind's Measurements with the own state; with noise the
    kind hands its messages themselves): every packet of the batch run is the per-agent run's."""
    sc = load_scenario(SCENARIOS / "tersoff-6.toml", list(sets)).with_overrides(duration_s=500.0)
    per_agent = run_in_process(sc, tmp_path / "agents", "p001", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "batch", "p001")
    assert batch.summary["batch"] == {"used": True, "why_not": None}
    n = assert_same_packets(tmp_path / "agents" / "run.mcap", tmp_path / "batch" / "run.mcap")
    assert n["truth"] == 101 and all(n[f"sc/{s}/sense/relative"] == 100 for s in sc.ids)
    assert batch.summary["delta_v_total_mps"] == per_agent.summary["delta_v_total_mps"] > 0


@pytest.mark.parametrize("name, seconds, sets", [
    ("surround-6", 21.0, ()),
    ("surround-6", 3.0, ("sensing.params.position_noise_m=0.5", "link.loss_probability=0.3", "link.range_m=300.0")),
    ("servicing-6", 22.0, ()),
], ids=["surround", "surround-noisy-lossy", "servicing"])
def test_link_missions_packets_are_the_per_agent_packets(tmp_path: Path, name: str, seconds: float,
                                                           sets: tuple[str, ...]) -> None:
    """Papers 003 and 004 (surround-6, servicing-6: mission Measurements kinds, a [link]): every packet
    of the batch run is the per-agent run's, the link channel's too: its `link_config` event, every
    transmission and delivery, the statistics every 10 s and at the end, the barrier of each step;
    with noise (paper 003's kind then hands its messages), loss and range drops of the link."""
    sc = load_scenario(SCENARIOS / f"{name}.toml", list(sets)).with_overrides(duration_s=seconds)
    per_agent = run_in_process(sc, tmp_path / "agents", "link", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "batch", "link")
    assert batch.summary["batch"] == {"used": True, "why_not": None}
    n = assert_same_packets(tmp_path / "agents" / "run.mcap", tmp_path / "batch" / "run.mcap")
    steps = round(seconds / sc.step_s)
    assert n["truth"] == n["sync/channel"] + 1 == steps + 1
    assert all(n[f"sc/{s}/act"] == n[f"isl/tx/{s}"] == steps for s in sc.ids)
    assert n["link/stats"] == len(range(0, steps, 100)) + 1  # every 10 s, and at the final tick
    rx = sum(n.get(f"isl/rx/{s}", 0) for s in sc.ids)
    drops = per_agent.summary["channel"]["totals"]
    assert rx == drops["rx_messages"] > 0 and batch.summary["channel"]["totals"] == drops
    for k in ("links", "link_columns", "pending_at_end"):  # (what the reports read of the channel's summary)
        assert batch.summary["channel"][k] == per_agent.summary["channel"][k], k
    if sets:
        assert drops["dropped_lost"] > 0 and drops["dropped_range"] > 0
    assert batch.summary["delta_v_total_mps"] == per_agent.summary["delta_v_total_mps"] > 0


def test_capture_packets_are_the_per_agent_packets(tmp_path: Path) -> None:
    """Paper 000 (capture-20: the landmarks kind's Measurements with (K, 3) items, commands with
    torques, a [link] whose range lets only some pairs talk): every packet of the batch run is the
    per-agent run's."""
    sc = load_scenario(SCENARIOS / "capture-20.toml").with_overrides(duration_s=3.0)
    per_agent = run_in_process(sc, tmp_path / "agents", "p000", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "batch", "p000")
    assert batch.summary["batch"] == {"used": True, "why_not": None}
    n = assert_same_packets(tmp_path / "agents" / "run.mcap", tmp_path / "batch" / "run.mcap")
    assert n["truth"] == 61 and all(n[f"sc/{s}/act"] == 60 for s in sc.ids)
    rx = {s: n.get(f"isl/rx/{s}", 0) for s in sc.ids}
    assert sum(rx.values()) == per_agent.summary["channel"]["totals"]["rx_messages"] > 0 and min(rx.values()) < max(rx.values())
    stims = [pb.Measurements.FromString(d) for t, _s, _l, d in _messages(tmp_path / "batch" / "run.mcap")
             if t.endswith("/sense/p000-landmarks")]
    assert any(len(it.shape) == 2 for s in stims for it in s.items)
    assert batch.summary["delta_v_total_mps"] == per_agent.summary["delta_v_total_mps"] > 0


def test_rejected_transmissions_packets_are_the_per_agent_packets(tmp_path: Path) -> None:
    """surround-6 with a payload limit below the servicers' 50 B packets (the leader's 41 B pass): the
    channel rejects every servicer packet and records a `rejected_packet` event for each of the first
    `max_events`, after the sender's telemetry; the batch run writes the same events in the same places."""
    sets = ["link.max_payload_bytes=45", "link.max_events=20"]
    sc = load_scenario(SCENARIOS / "surround-6.toml", sets).with_overrides(duration_s=2.0)
    per_agent = run_in_process(sc, tmp_path / "agents", "rej", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "batch", "rej")
    assert batch.summary["batch"]["used"]
    n = assert_same_packets(tmp_path / "agents" / "run.mcap", tmp_path / "batch" / "run.mcap")
    events = [pb.Event.FromString(d) for t, _s, _l, d in _messages(tmp_path / "batch" / "run.mcap") if t == "event"]
    rejected = [e for e in events if e.kind == "rejected_packet"]
    assert len(rejected) == 20 and all("oversized payload" in e.detail for e in rejected)
    assert n["foxglove/log"] == n["event"] and n["isl/rx/ssat1"] == 20 and "isl/rx/lsat" not in n
    assert batch.summary["channel"]["totals"] == per_agent.summary["channel"]["totals"]
    assert per_agent.summary["channel"]["totals"]["rejected_packets"] == 6 * 20
