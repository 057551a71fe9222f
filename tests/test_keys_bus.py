"""Key expressions (contract) and the in-memory bus semantics."""
from __future__ import annotations

import pytest

from swarmhil.bus.base import key_matches
from swarmhil.bus.keys import Keys
from swarmhil.bus.memory import MemoryBus


def test_contract_keys() -> None:
    k = Keys("r1")
    assert k.clock == "swarm/r1/clock"
    assert k.truth == "swarm/r1/truth"
    assert k.sense("sc01", "rel") == "swarm/r1/sc/sc01/sense/rel"
    assert k.act("sc01") == "swarm/r1/sc/sc01/act"
    assert k.tm("sc01") == "swarm/r1/sc/sc01/tm"
    assert k.isl_tx("a") == "swarm/r1/isl/tx/a"
    assert k.isl_rx("a") == "swarm/r1/isl/rx/a"
    assert k.link_stats == "swarm/r1/link/stats"
    assert k.alive("plant") == "swarm/r1/alive/plant"
    assert k.parse("swarm/r1/sc/x/sense/scene") == ("sense", "x", "scene")
    with pytest.raises(ValueError, match="not under"):
        k.parse("swarm/r2/truth")
    with pytest.raises(ValueError, match="not a key"):
        k.parse("swarm/r1/sc/x/bogus")


@pytest.mark.parametrize("bad", ["", "a/b", "a*", "x$y", "has space", "q?"])
def test_ids_that_would_break_keys_are_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="invalid"):
        Keys("r").act(bad)


def test_key_matching() -> None:
    assert key_matches("swarm/r/**", "swarm/r/sc/a/act")
    assert key_matches("swarm/r/sc/*/act", "swarm/r/sc/a/act")
    assert not key_matches("swarm/r/sc/*/act", "swarm/r/sc/a/tm")
    assert not key_matches("swarm/r/*", "swarm/r/sc/a")
    assert key_matches("swarm/r/**", "swarm/r")  # ** matches zero chunks, as in Zenoh


def test_memory_bus_breadth_first_and_liveliness() -> None:
    bus = MemoryBus()
    order: list[str] = []
    bus.subscribe("a", lambda k, p: (order.append("a1"), bus.publish("b", b"")))
    bus.subscribe("a", lambda k, p: order.append("a2"))
    bus.subscribe("b", lambda k, p: order.append("b"))
    bus.publish("a", b"x")
    assert order == ["a1", "a2", "b"]  # nested publish runs after the current delivery
    seen: list[tuple[str, bool]] = []
    tok = bus.declare_liveliness("swarm/r/alive/x")
    bus.watch_liveliness("swarm/r/alive/*", lambda k, alive: seen.append((k, alive)))
    tok.undeclare()
    assert seen == [("swarm/r/alive/x", True), ("swarm/r/alive/x", False)]


def test_memory_bus_isolates_a_failing_callback() -> None:
    """Like the Zenoh dispatcher: one node's exception is logged and counted, the others still get the sample."""
    bus = MemoryBus()
    got: list[str] = []
    bus.subscribe("k", lambda k, p: 1 / 0)
    bus.subscribe("k", lambda k, p: got.append(k))
    bus.publish("k", b"")
    assert got == ["k"] and bus.callback_errors == 1
