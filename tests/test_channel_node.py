"""The channel companion on the in-memory bus: lockstep barrier, determinism, bad input."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.link import node as channel_node
from swarmhil.bus.codec import header, vec
from swarmhil.bus.keys import Keys
from swarmhil.bus.memory import MemoryBus
from swarmhil.deploy.scenario import ScenarioError, load_scenario, parse_scenario

from conftest import read_mcap

RUN = "chan"
IDS = ["a", "b", "c"]

SMALL = """
[run]
name = "{name}"
duration_s = {duration}
step_s = 10.0
seed = 11

[controller]
name = "null"

[dispersion]
count = 5
sigma_roe_m = [30.0, 40.0, 30.0, 30.0, 30.0, 30.0]
along_track_spacing_m = 200.0

[link]
range_m = 400.0
loss_probability = {loss}
overhead_bytes = 24
stats_period_s = 50.0

[beacon]
period_s = {period}
"""


def write_small(tmp: Path, name: str = "link5", duration: float = 300.0, loss: float = 0.25, period: float = 10.0) -> Path:
    p = tmp / f"{name}.toml"
    p.write_text(SMALL.format(name=name, duration=duration, loss=loss, period=period))
    return p


def _scenario(link: dict) -> object:
    doc = {"run": {"name": "chan", "duration_s": 100.0, "step_s": 10.0, "seed": 4},
           "spacecraft": [{"id": s, "roe_m": [0, 100.0 * i, 0, 0, 0, 0]} for i, s in enumerate(IDS)], "link": link}
    return parse_scenario(doc, "chan.toml")


class FakePlant:
    """Publishes what the plant would: tick k and truth k (before the stimuli), then waits for the barrier."""

    def __init__(self, bus: MemoryBus, positions: dict[str, list[float]]) -> None:
        self.bus, self.k, self.keys = bus, Keys(RUN), Keys(RUN)
        self.positions = positions
        self.syncs: list[int] = []
        bus.subscribe(self.keys.sync("channel"), lambda _k, p: self.syncs.append(pb.Tick.FromString(p).header.step))

    def tick(self, step: int, final: bool = False) -> None:
        t = pb.Tick(header=header(RUN, "plant", step, 10.0 * step, step), step_s=10.0, alive=IDS, final=final)
        self.bus.publish(self.keys.clock, t.SerializeToString())

    def truth(self, step: int) -> None:
        tr = pb.Truth(header=header(RUN, "plant", step, 10.0 * step, step), semi_major_axis_m=6878137.0)
        for s, p in self.positions.items():
            tr.bodies.append(pb.BodyState(id=s, position_m=vec(p), alive=True))
        self.bus.publish(self.keys.truth, tr.SerializeToString())


def _tx(bus: MemoryBus, key_id: str, src: str, step: int, dst: str = "", payload: bytes = b"hello", run: str = RUN,
        sent_t: float | None = None) -> None:
    pkt = pb.IslPacket(header=header(run, key_id, step, 10.0 * step, step), src=src, dst=dst, type="beacon",
                       payload=payload, sent_t=10.0 * step if sent_t is None else sent_t)
    bus.publish(Keys(RUN).isl_tx(key_id), pkt.SerializeToString())


def _act(bus: MemoryBus, sid: str, step: int) -> None:
    cmd = pb.ActuatorCommand(header=header(RUN, sid, step, 10.0 * step, step), accel_mps2=vec([0, 0, 0]))
    bus.publish(Keys(RUN).act(sid), cmd.SerializeToString())


def test_barrier_deliveries_and_rejections_on_a_fake_plant(tmp_path: Path) -> None:
    bus = MemoryBus()
    sc = _scenario({"range_m": 150.0, "max_payload_bytes": 64})
    plant = FakePlant(bus, {"a": [0, 0, 0], "b": [0, 100.0, 0], "c": [0, 200.0, 0]})
    rx: dict[str, list[pb.IslPacket]] = {s: [] for s in IDS}
    for s in IDS:
        bus.subscribe(Keys(RUN).isl_rx(s), lambda _k, p, s=s: rx[s].append(pb.IslPacket.FromString(p)))
    events: list[pb.Event] = []
    bus.subscribe(Keys(RUN).event, lambda _k, p: events.append(pb.Event.FromString(p)))
    node = channel_node.start(bus, RUN, sc, tmp_path, {})
    steps = 6
    for k in range(steps):
        plant.tick(k)
        plant.truth(k)
        _tx(bus, "a", "a", k)                                  # valid broadcast: b in range, c not
        _tx(bus, "c", "c", k, dst="b")                         # valid, addressed: b in range of c
        _tx(bus, "b", "a", k)                                  # forged source
        bus.publish(Keys(RUN).isl_tx("b"), b"\xff\xff\xff")  # malformed
        _tx(bus, "b", "b", k, payload=b"x" * 65)               # oversized
        _tx(bus, "b", "b", k, dst="nobody")                    # unknown destination
        _tx(bus, "zz", "zz", k)                                # unknown source
        _tx(bus, "b", "b", k, run="other")                     # foreign run
        _tx(bus, "b", "b", k, sent_t=math.nan)                 # non-finite
        for s in IDS:
            _act(bus, s, k)
        assert plant.syncs[-1] == k  # the barrier of step k came once every agent had acted
    plant.tick(steps, final=True)
    summary = node.close()
    assert plant.syncs == list(range(steps))
    # a broadcast from a reaches b only; c's addressed packets reach b; nothing reaches c
    assert [(p.src, p.dst) for p in rx["b"]] == [("a", ""), ("c", "b")] * steps
    assert rx["a"] == [] and rx["c"] == []
    # delivered at the receiver step after sending (the truth of step k comes with tick k)
    assert [p.header.step for p in rx["b"][::2]] == [k + 1 for k in range(steps)]
    assert [p.sent_t for p in rx["b"][::2]] == [10.0 * k for k in range(steps)]
    tot = summary["totals"]
    assert tot["tx_messages"] == 2 * steps and tot["rx_messages"] == 2 * steps
    assert tot["dropped_range"] == steps and tot["rx_wire_bytes"] == 2 * steps * 5
    assert tot["rejected_packets"] == 7 * steps
    assert summary["rejected_by_reason"] == {"forged source": steps, "malformed": 3 * steps, "oversized payload": steps,
                                             "unknown destination": steps, "unknown source": steps}
    rej = [e for e in events if e.kind == "rejected_packet"]
    assert len(rej) == 7 * steps and all(e.header.source == "channel" for e in rej)
    assert any("forged source" in e.detail and e.subject == "b" for e in rej)
    assert summary["pending_at_end"] == {"queued": 0, "unevaluated": 0, "scheduled_deliveries": 0}


def test_enabled_and_validation() -> None:
    assert channel_node.enabled(_scenario({"range_m": 500.0}), {})
    assert not channel_node.enabled(_scenario({"enabled": False, "range_m": 500.0}), {})
    doc = {"run": {"name": "x"}, "spacecraft": [{"id": "a", "roe_m": [0] * 6}]}
    assert not channel_node.enabled(parse_scenario(doc, "x.toml"), {})
    with pytest.raises(ScenarioError, match=r"chan.toml: \[link\].range_m"):  # at load time, naming the field
        _scenario({"range_m": -5.0})
    assert channel_node.LOCKSTEP_BARRIER is True


def _rx_samples(path: Path) -> list[tuple[str, bytes]]:
    return [(t, m.SerializeToString()) for t, _lt, _pt, m in read_mcap(path) if t.startswith("isl/rx/")]


def test_in_process_runs_are_deterministic(tmp_path: Path) -> None:
    from swarmhil.deploy.launcher import run_in_process

    sc = load_scenario(write_small(tmp_path, duration=200.0))
    r1 = run_in_process(sc, tmp_path / "r1", "det")
    r2 = run_in_process(sc, tmp_path / "r2", "det")
    a, b = _rx_samples(tmp_path / "r1" / "run.mcap"), _rx_samples(tmp_path / "r2" / "run.mcap")
    assert len(a) > 30 and a == b
    c1, c2 = r1.summary["channel"], r2.summary["channel"]
    assert c1["links"] == c2["links"] and c1["totals"]["dropped_lost"] > 0 and c1["totals"]["dropped_range"] > 0
    assert c1["windows"] == r1.summary["steps"] and c1["forced_windows"] == 0
    assert not r1.summary["missed_deadlines"] and not r1.summary["dead_agents"]


class RogueBus(MemoryBus):
    """The in-memory bus with a misbehaving participant: bad ISL packets on every tick."""

    def __init__(self) -> None:
        super().__init__()
        self.subscribe("swarm/*/clock", self._rogue)

    def _rogue(self, key: str, payload: bytes) -> None:
        run = key.split("/")[1]
        k = Keys(run)
        tick = pb.Tick.FromString(payload)
        step = tick.header.step

        def pkt(src: str, dst: str = "", n: int = 4) -> bytes:
            return pb.IslPacket(header=header(run, src, step, tick.header.t, 0), src=src, dst=dst, type="evil",
                                payload=b"e" * n, sent_t=tick.header.t).SerializeToString()

        self.publish(k.isl_tx("sc02"), pkt("sc01"))                # sc02 transmitting as sc01
        self.publish(k.isl_tx("sc03"), b"\x0a\xff\xff\xff")       # malformed
        self.publish(k.isl_tx("sc04"), pkt("sc04", n=100000))      # oversized
        self.publish(k.isl_tx("sc05"), pkt("sc05", dst="sc99"))    # unknown destination


def test_bad_packets_are_rejected_counted_and_recorded_while_the_run_continues(tmp_path: Path,
                                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.dashboards.bandwidth.accounting import consistency
    from swarmhil.dashboards.bandwidth.read import read_link_traffic

    monkeypatch.setattr("swarmhil.bus.memory.MemoryBus", RogueBus)
    sc = load_scenario(write_small(tmp_path, duration=100.0))
    res = run_in_process(sc, tmp_path / "rogue", "rogue")
    s = res.summary
    assert s["steps"] == 10 and not s["dead_agents"] and not s["missed_deadlines"]
    ticks = s["steps"] + 1
    ch = s["channel"]
    assert ch["rejected_by_reason"] == {"forged source": ticks, "malformed": ticks, "oversized payload": ticks,
                                        "unknown destination": ticks}
    assert ch["totals"]["tx_messages"] == 5 * 10  # the agents' own beacons, every step
    msgs = read_mcap(tmp_path / "rogue" / "run.mcap")
    ev = [m for t, _l, _p, m in msgs if t == "event" and m.kind == "rejected_packet"]
    assert len(ev) == 4 * ticks
    assert not any(m.type == "evil" for t, _l, _p, m in msgs if t.startswith("isl/rx/"))
    lt = read_link_traffic(tmp_path / "rogue")
    assert lt.rejected_tx == {"forged source": ticks, "malformed": ticks, "oversized payload": ticks,
                              "unknown destination": ticks}
    assert all(ok for *_x, ok in consistency(lt))


def test_truth_positions_reach_the_model_by_id(tmp_path: Path) -> None:
    """Bodies in the truth in any order, and unknown bodies, map onto the scenario's ids."""
    bus = MemoryBus()
    node = channel_node.start(bus, RUN, _scenario({"range_m": 1.0}), tmp_path, {})
    tr = pb.Truth(header=header(RUN, "plant", 3, 30.0, 0), semi_major_axis_m=7e6)
    for s, x in (("c", 3.0), ("zz", 9.0), ("a", 1.0)):
        tr.bodies.append(pb.BodyState(id=s, position_m=vec([x, 0, 0])))
    bus.publish(Keys(RUN).truth, tr.SerializeToString())
    pos, a_m = node.model._truth[3]
    assert a_m == 7e6 and pos[0, 0] == 1.0 and pos[2, 0] == 3.0 and np.isnan(pos[1]).all()
    node.close()


def _act_n(bus: MemoryBus, sid: str, step: int, n_tx: int) -> None:
    cmd = pb.ActuatorCommand(header=header(RUN, sid, step, 10.0 * step, step), accel_mps2=vec([0, 0, 0]),
                             isl_tx_count=n_tx)
    bus.publish(Keys(RUN).act(sid), cmd.SerializeToString())


def _rx_log(bus: MemoryBus) -> list[tuple[str, str, float, int]]:
    got: list[tuple[str, str, float, int]] = []
    for s in IDS:
        bus.subscribe(Keys(RUN).isl_rx(s), lambda _k, p, s=s: got.append(
            (s, pb.IslPacket.FromString(p).src, pb.IslPacket.FromString(p).sent_t, pb.IslPacket.FromString(p).header.step)))
    return got


POS = {"a": [0, 0, 0], "b": [0, 100.0, 0], "c": [0, 200.0, 0]}


def test_packets_and_commands_before_their_tick_are_held_and_dated_by_their_own_step(tmp_path: Path) -> None:
    """Issue 10: everything of step k arrives before tick k; deliveries as if in order."""
    bus = MemoryBus()
    plant = FakePlant(bus, POS)
    got = _rx_log(bus)
    node = channel_node.start(bus, RUN, _scenario({"range_m": 150.0}), tmp_path, {})
    for k in range(4):
        _tx(bus, "a", "a", k)                 # before tick k: held (the channel is still at step k-1)
        for s in IDS:
            _act_n(bus, s, k, 1 if s == "a" else 0)
        assert plant.syncs == list(range(k))  # no barrier for step k before its tick and truth
        plant.tick(k)
        assert plant.syncs == list(range(k))  # ... nor before its truth
        plant.truth(k)
        assert plant.syncs == list(range(k + 1))
    plant.tick(4, final=True)
    s = node.close()
    assert sorted(got) == sorted(("b", "a", 10.0 * k, k + 1) for k in range(4))
    assert s["early_packets"] == 4 and s["early_commands"] == 12 and s["forced_windows"] == 0 and s["late_packets"] == 0


def test_a_window_waits_for_every_packet_its_commands_announce(tmp_path: Path) -> None:
    bus = MemoryBus()
    plant = FakePlant(bus, POS)
    got = _rx_log(bus)
    node = channel_node.start(bus, RUN, _scenario({"range_m": 150.0}), tmp_path, {})
    plant.tick(0)
    plant.truth(0)
    for s in IDS:
        _act_n(bus, s, 0, 2 if s == "b" else 0)  # b's command overtook its two packets
    assert plant.syncs == []
    _tx(bus, "b", "b", 0)
    assert plant.syncs == []
    _tx(bus, "b", "b", 0, dst="c")
    assert plant.syncs == [0]
    plant.tick(1, final=True)
    s = node.close()
    assert sorted(got) == [("a", "b", 0.0, 1), ("c", "b", 0.0, 1), ("c", "b", 0.0, 1)]
    assert s["waited_for_packets"] == 1 and s["late_packets"] == 0


def test_late_packets_keep_their_send_step_and_bad_steps_are_rejected(tmp_path: Path) -> None:
    """A packet after its window (the plant moved on without it) is range-checked against the truth
    of its own step and delivered at the next window; a packet dated beyond the next step is rejected."""
    bus = MemoryBus()
    plant = FakePlant(bus, dict(POS))
    got = _rx_log(bus)
    node = channel_node.start(bus, RUN, _scenario({"range_m": 150.0}), tmp_path, {})
    plant.tick(0)
    plant.truth(0)
    for s in ("a", "c"):
        _act_n(bus, s, 0, 0)
    plant.tick(1)                                  # b never acted: the plant moved on (forced window 0)
    plant.positions["a"] = [0, 1000.0, 0]          # at step 1 a is out of everyone's range ...
    plant.truth(1)
    _tx(bus, "a", "a", 0)                          # ... but its late packet of step 0 was sent in range of b
    _tx(bus, "a", "a", 7)                          # dated far ahead: rejected
    for s in IDS:
        _act_n(bus, s, 1, 0)
    plant.tick(2, final=True)
    s = node.close()
    assert got == [("b", "a", 0.0, 2)]
    assert s["late_packets"] == 1 and s["forced_windows"] == 1
    assert s["rejected_by_reason"] == {"bad step": 1}
