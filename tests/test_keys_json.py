"""bus/keys.json (the key -> message-type map as data) matches the code that publishes and records."""
from __future__ import annotations

import json

from conftest import ROOT


def test_committed_keys_json_is_what_the_code_generates() -> None:
    from swarmhil.bus.keys_json import PATH, render

    assert PATH == ROOT / "bus" / "keys.json"
    assert PATH.read_text() == render(), "bus/keys.json is stale: run `make proto` (python -m swarmhil.bus.keys_json)"


def test_every_key_of_the_builder_has_the_type_keys_json_gives() -> None:
    from swarmhil.bus.codec import encoding_of_key, message_type_of_topic
    from swarmhil.bus.keys import Keys

    doc = json.loads((ROOT / "bus" / "keys.json").read_text())
    k = Keys("r")

    def lookup(key: str) -> str | None:
        parts = key[len("swarm/r/"):].split("/")
        for e in doc["keys"]:
            pat = e["key"].split("/")
            if len(pat) == len(parts) and all(p in ("*", x) for p, x in zip(pat, parts)):
                return e["type"]
        raise AssertionError(key)

    keys = [k.clock, k.truth, k.event, k.link_stats, k.sync("channel"), k.sense("a", "rel"), k.sense("a", "scene"),
            k.sense("a", "landmarks"), k.act("a"), k.tm("a"), k.tm_image("a"), k.isl_tx("a"), k.isl_rx("b"),
            k.alive("plant")]
    for key in keys:
        cls = message_type_of_topic(key)
        assert lookup(key) == (cls.DESCRIPTOR.full_name if cls else None), key
        assert message_type_of_topic(k.topic(key)) is cls  # the MCAP topic maps the same
        assert encoding_of_key(key) == (f"application/protobuf;{cls.DESCRIPTOR.full_name}" if cls else None)
    assert k.topic(k.isl_rx("b")) == "isl/rx/b" and k.topic("swarm/other/truth") == "swarm/other/truth"
