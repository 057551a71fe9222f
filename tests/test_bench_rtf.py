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
