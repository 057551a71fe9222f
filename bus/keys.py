"""Key expressions of a run: the one place they are spelled (DESIGN.md "Key expressions (contract)").

    swarm/<run>/clock                 plant -> all        Tick
    swarm/<run>/truth                 plant -> recorder   Truth
    swarm/<run>/sc/<id>/sense/<kind>  plant -> agent id   RelStimulus | SceneStimulus
    swarm/<run>/sc/<id>/act           agent id -> plant   ActuatorCommand
    swarm/<run>/sc/<id>/tm            agent id -> all     Telemetry
    swarm/<run>/isl/tx/<id>           agent id -> channel IslPacket
    swarm/<run>/isl/rx/<id>           channel -> agent id IslPacket
    swarm/<run>/link/stats            channel -> all      LinkStats
    swarm/<run>/alive/<process>       liveliness tokens
    swarm/<run>/event                 any -> all          Event (project addition, not in the contract list)
    swarm/<run>/faults                plant -> all        Event: each [[fault]]'s start and end (project addition, issue 27)
    swarm/<run>/sync/<process>        companion -> plant  Tick: lockstep barrier "done with step k" (project addition)
"""
from __future__ import annotations

import re

ROOT = "swarm"
_TOKEN = re.compile(r"^[A-Za-z0-9_.\-]+$")


def check_token(value: str, what: str = "id") -> str:
    """Reject ids that would break a key expression (`/`, `*`, `$`, `#`, `?`, empty)."""
    if not isinstance(value, str) or not _TOKEN.match(value):
        raise ValueError(f"invalid {what} {value!r}: use letters, digits, '_', '-', '.'")
    return value


class Keys:
    """Key-expression builder for one run."""

    def __init__(self, run: str) -> None:
        self.run = check_token(run, "run id")
        self.base = f"{ROOT}/{self.run}"

    @property
    def all(self) -> str:
        return f"{self.base}/**"

    # control keys outside swarm/<run>/** (so the recorder does not record them): the launcher's
    # flush handshake with the recorder (bus/recorder.py)
    @property
    def control_all(self) -> str:
        return f"swarmctl/{self.run}/**"

    @property
    def recorder_flush(self) -> str:
        return f"swarmctl/{self.run}/recorder/flush"

    @property
    def recorder_ack(self) -> str:
        return f"swarmctl/{self.run}/recorder/ack"

    @property
    def clock(self) -> str:
        return f"{self.base}/clock"

    @property
    def truth(self) -> str:
        return f"{self.base}/truth"

    @property
    def event(self) -> str:
        return f"{self.base}/event"

    @property
    def faults(self) -> str:
        return f"{self.base}/faults"

    @property
    def link_stats(self) -> str:
        return f"{self.base}/link/stats"

    def sync(self, process: str) -> str:
        return f"{self.base}/sync/{check_token(process, 'process name')}"

    @property
    def sync_all(self) -> str:
        return f"{self.base}/sync/*"

    def sense(self, sc: str, kind: str) -> str:
        return f"{self.base}/sc/{check_token(sc)}/sense/{check_token(kind, 'sensor kind')}"

    def act(self, sc: str) -> str:
        return f"{self.base}/sc/{check_token(sc)}/act"

    @property
    def act_all(self) -> str:
        return f"{self.base}/sc/*/act"

    def tm(self, sc: str) -> str:
        return f"{self.base}/sc/{check_token(sc)}/tm"

    def tm_image(self, sc: str) -> str:
        """Debug camera frames (foxglove.CompressedImage), under the agent's telemetry key."""
        return f"{self.base}/sc/{check_token(sc)}/tm/image"

    @property
    def tm_all(self) -> str:
        return f"{self.base}/sc/*/tm"

    def isl_tx(self, sc: str) -> str:
        return f"{self.base}/isl/tx/{check_token(sc)}"

    @property
    def isl_tx_all(self) -> str:
        return f"{self.base}/isl/tx/*"

    def isl_rx(self, sc: str) -> str:
        return f"{self.base}/isl/rx/{check_token(sc)}"

    def alive(self, process: str) -> str:
        return f"{self.base}/alive/{check_token(process, 'process name')}"

    @property
    def alive_all(self) -> str:
        return f"{self.base}/alive/*"

    def parse(self, key: str) -> tuple[str, str | None, str | None]:
        """Split a key of this run into (topic kind, spacecraft/process id, sensor kind).

        Kinds: clock, truth, event, faults, link_stats, sense, act, tm, isl_tx, isl_rx, alive.
        Raises ValueError for a key outside the contract.
        """
        prefix = self.base + "/"
        if not key.startswith(prefix):
            raise ValueError(f"key {key!r} is not under {self.base}/")
        return parse_topic(key[len(prefix):], key)

    def topic(self, key: str) -> str:
        """The MCAP topic of a key of this run: the key without its `swarm/<run>/` prefix
        (DESIGN.md "MCAP (contract)"); a key of another run or outside `swarm/` is kept whole."""
        prefix = self.base + "/"
        return key[len(prefix):] if key.startswith(prefix) else key


def parse_topic(topic: str, key: str | None = None) -> tuple[str, str | None, str | None]:
    """(kind, id, sensor kind) of a key relative to `swarm/<run>/` (an MCAP topic); see Keys.parse."""
    parts = topic.split("/")
    match parts:
        case ["clock"] | ["truth"] | ["event"] | ["faults"]:
            return parts[0], None, None
        case ["link", "stats"]:
            return "link_stats", None, None
        case ["sc", sc, "sense", kind]:
            return "sense", sc, kind
        case ["sc", sc, "act"]:
            return "act", sc, None
        case ["sc", sc, "tm"]:
            return "tm", sc, None
        case ["sc", sc, "tm", "image"]:
            return "tm_image", sc, None
        case ["isl", "tx", sc]:
            return "isl_tx", sc, None
        case ["isl", "rx", sc]:
            return "isl_rx", sc, None
        case ["alive", proc]:
            return "alive", proc, None
        case ["sync", proc]:
            return "sync", proc, None
    raise ValueError(f"key {key or topic!r} is not a key of the swarmhil contract")


def split_topic(topic: str) -> tuple[str | None, str]:
    """(run, relative topic) of an MCAP topic: a current recording's topics are relative
    (`truth`, `sc/sc01/act`; run None, take it from the metadata `swarmhil.run`); recordings made
    before the MCAP contract carried the whole key (`swarm/<run>/truth`). Readers accept both."""
    parts = topic.split("/", 2)
    if len(parts) == 3 and parts[0] == ROOT:
        return parts[1], parts[2]
    return None, topic


def run_of(key: str) -> str:
    """The <run> part of a swarm/<run>/... key."""
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != ROOT:
        raise ValueError(f"key {key!r} is not a swarm/<run>/... key")
    return parts[1]
