"""bus/keys.json: the key -> message-type map of the contract as data (DESIGN.md "MCAP (contract)").

`python -m swarmhil.bus.keys_json` (run by `make proto`) writes it from the code (bus/keys.py parse_topic,
bus/codec.py message_type_of_topic); tests/test_keys_json.py checks the committed file matches.
A client that imports nothing of the project reads it with bus/swarmhil.proto: strip
`swarm/<run>/` from a key, take the first entry whose `key` pattern matches (`*` = one chunk),
decode the payload as `type`. Live samples carry the same type as their Zenoh encoding schema.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from swarmhil.bus.codec import message_type_of_topic

PATH = Path(__file__).with_name("keys.json")

# (pattern relative to swarm/<run>/, an example key that matches it, publisher -> subscriber)
ENTRIES: list[tuple[str, str, str]] = [
    ("clock", "clock", "plant -> all"),
    ("truth", "truth", "plant -> recorder"),
    ("sc/*/sense/rel", "sc/x/sense/rel", "plant -> agent"),
    ("sc/*/sense/scene", "sc/x/sense/scene", "plant -> agent"),
    ("sc/*/sense/*", "sc/x/sense/other", "plant -> agent (mission sensing kinds)"),
    ("sc/*/act", "sc/x/act", "agent -> plant"),
    ("sc/*/tm", "sc/x/tm", "agent -> all"),
    ("sc/*/tm/image", "sc/x/tm/image", "agent -> all (debug camera frames)"),
    ("isl/tx/*", "isl/tx/x", "agent -> channel"),
    ("isl/rx/*", "isl/rx/x", "channel -> agent"),
    ("link/stats", "link/stats", "channel -> all"),
    ("event", "event", "any -> all"),
    ("faults", "faults", "plant -> all (each [[fault]]'s start and end)"),
    ("sync/*", "sync/x", "companion -> plant (lockstep barrier)"),
    ("alive/*", "alive/x", "liveliness tokens (no payload)"),
]

# Channels only the recording has, written by the recorder from the truth (bus/foxglove_scene.py).
RECORDING_ONLY: list[tuple[str, str]] = [
    ("foxglove/tf", "foxglove.FrameTransforms"),
    ("foxglove/scene", "foxglove.SceneUpdate"),
    ("foxglove/log", "foxglove.Log"),
]


def build() -> dict[str, Any]:
    keys = []
    for pattern, example, flow in ENTRIES:
        cls = message_type_of_topic(example)
        keys.append({"key": pattern, "type": cls.DESCRIPTOR.full_name if cls is not None else None, "flow": flow})
    return {
        "prefix": "swarm/<run>/",
        "proto": "swarmhil.proto",
        "encoding": "application/protobuf;<type>",
        "match": "first entry whose key pattern matches the key without its prefix; '*' is one chunk",
        "keys": keys,
        "recording_only": [{"topic": t, "type": ty} for t, ty in RECORDING_ONLY],
    }


def render() -> str:
    return json.dumps(build(), indent=1) + "\n"


if __name__ == "__main__":
    PATH.write_text(render())
    print(f"wrote {PATH}")
