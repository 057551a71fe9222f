"""bench/rtf_curve.py's pure parts (the curve itself is a bench, `swarmhil claims --bench --only rtf.`):
the paper 000 scenario cut to its first N spacecraft is a valid scenario of N, and a run's misses
count both missed deadlines and late commands."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from conftest import ROOT

sys.path.insert(0, str(ROOT / "bench"))

from rtf_curve import P000, first_spacecraft, misses  # noqa: E402


def test_first_spacecraft_gives_a_valid_scenario_of_n(tmp_path: Path) -> None:
    from swarmhil.deploy.scenario import load_scenario

    path = tmp_path / "capture-5.toml"
    path.write_text(first_spacecraft(P000.read_text(), 5))
    sc = load_scenario(path)
    assert [s.id for s in sc.spacecraft] == [s.id for s in load_scenario(P000).spacecraft][:5]
    with pytest.raises(ValueError, match="fewer than 25"):
        first_spacecraft(P000.read_text(), 25)


def test_misses_count_deadlines_and_late_commands() -> None:
    assert misses({"missed_deadlines": {"a0": 2, "a1": 1}, "late_commands": 4}) == 7
    assert misses({"missed_deadlines": {}, "late_commands": 0}) == 0
    assert misses({}) == 0


def test_the_floor_takes_a_recordings_message_sizes(tmp_path: Path) -> None:
    """bench/bus_floor.py --sizes-from: the mean payload of each class (clock, truth, stimulus of any
    sensing kind, command, telemetry) over a recording written with the standard MCAP writer; other
    topics are not counted, and a recording without one of the classes is refused, naming it."""
    from mcap.writer import Writer

    from bus_floor import SIZES, sizes_from_recording

    path = tmp_path / "r.mcap"
    payloads = {"clock": [100, 102], "truth": [2000, 3000], "sc/a/sense/p000-landmarks": [300, 400],
                "sc/b/sense/rel": [200], "sc/a/act": [50, 60], "sc/a/tm": [70], "isl/tx/a": [999], "sc/a/tm/image": [5000]}
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("raw", "none", b"")
        for k, (topic, sizes) in enumerate(payloads.items()):
            ch = w.register_channel(topic, "none", schema)
            for i, n in enumerate(sizes):
                w.add_message(ch, log_time=k * 10 + i, data=bytes(n), publish_time=k * 10 + i)
        w.finish()
    assert sizes_from_recording(path) == {"clock": 101, "truth": 2500, "sense": 300, "act": 55, "tm": 70}
    assert set(SIZES) == {"clock", "truth", "sense", "act", "tm"}
    partial = tmp_path / "p.mcap"
    with open(partial, "wb") as f:
        w = Writer(f)
        w.start()
        ch = w.register_channel("truth", "none", w.register_schema("raw", "none", b""))
        w.add_message(ch, log_time=0, data=b"x", publish_time=0)
        w.finish()
    with pytest.raises(SystemExit, match="no clock, sense, act, tm messages"):
        sizes_from_recording(partial)
