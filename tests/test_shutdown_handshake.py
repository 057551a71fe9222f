"""Shutdown without sleeps (issue 10): the recorder's flush handshake, and the router's port
retry when the free port is taken before Zenoh binds it."""
from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.memory import MemoryBus
from swarmhil.bus.recorder import RecorderNode, ack_key, flush_key
from conftest import read_mcap


def test_recorder_answers_a_flush_with_what_it_wrote_and_whether_run_end_is_in(tmp_path: Path) -> None:
    bus = MemoryBus()
    node = RecorderNode(bus, "r", tmp_path / "run.mcap")
    acks: list[dict] = []
    bus.subscribe(ack_key("r"), lambda _k, p: acks.append(json.loads(p)))
    truth = pb.Truth(header=pb.Header(run="r", source="plant", step=3, t=30.0))
    bus.publish("swarm/r/truth", truth.SerializeToString())
    bus.publish(flush_key("r"), b"n1")
    # a truth is recorded with its Foxglove frame transforms and scene (MCAP contract)
    assert acks == [{"nonce": "n1", "messages": 3, "by_topic": {"truth": 1, "foxglove/tf": 1, "foxglove/scene": 1},
                     "run_end": False}]
    # another source's run_end does not count; the plant's does
    for source in ("agent", "plant"):
        ev = pb.Event(header=pb.Header(run="r", source=source, step=3, t=30.0), kind="run_end", subject=source)
        bus.publish("swarm/r/event", ev.SerializeToString())
        bus.publish(flush_key("r"), f"after-{source}".encode())
    # each event is recorded with its foxglove.Log twin
    assert [(a["nonce"], a["messages"], a["run_end"]) for a in acks[1:]] == [("after-agent", 5, False), ("after-plant", 7, True)]
    node.close()
    # the handshake itself is not recorded (outside swarm/<run>/**)
    topics = [t for t, *_ in read_mcap(tmp_path / "run.mcap")]
    assert [t for t in topics if not t.startswith("foxglove/")] == ["truth", "event", "event"]


def test_router_takes_another_port_when_its_free_port_was_taken_meanwhile() -> None:
    from swarmhil.bus.zenoh_bus import free_loopback_port, open_loopback_router

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        busy = taken.getsockname()[1]
        picks = [busy, busy]  # the race: twice a port that another process bound after it was picked

        def source() -> int:
            return picks.pop(0) if picks else free_loopback_port()

        router, ep = open_loopback_router(port_source=source)
        try:
            assert picks == [] and ep != f"tcp/127.0.0.1:{busy}"
        finally:
            router.close()
        # out of attempts: the collision is raised, not hidden
        import zenoh

        with pytest.raises(zenoh.ZError, match="Address already in use"):
            open_loopback_router(attempts=2, port_source=lambda: busy)
