"""The report's flight-software timing section (issue 26, dashboards/sections/timing.py): each agent's
compute time per step against a recomputation from the MCAP with the standard reader and the
standard library's quantiles (not the section's code), and the flag of a p99 over the real-time deadline."""
from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import SCENARIOS, read_mcap


def compute_by_hand(mcap: Path) -> dict[str, list[float]]:
    """{agent id: compute_s of each of its Telemetry messages} decoded with the standard readers only."""
    out: dict[str, list[float]] = {}
    for topic, _lt, _pt, m in read_mcap(mcap):
        parts = topic.split("/")
        if len(parts) == 3 and parts[0] == "sc" and parts[2] == "tm":
            out.setdefault(parts[1], []).append(m.compute_s)
    return out


def expected(xs: list[float]) -> tuple[int, float, float, float]:
    """steps, p50, p99 (linear interpolation between order statistics, as numpy's default), max."""
    q = statistics.quantiles(xs, n=100, method="inclusive")
    return len(xs), q[49], q[98], max(xs)


def run_and_report(tmp: Path, *args: str) -> tuple[dict, str]:
    from swarmhil.deploy.cli import main

    out = tmp / "run"
    res = CliRunner().invoke(main, ["run", str(SCENARIOS / "sabatini-2-collision.toml"), "--in-process",
                                    "--duration", "600", "--out", str(out), *args])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(out), "--no-vector"])
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text()), (out / "report" / "index.html").read_text()


def check_against_mcap(metrics: dict, mcap: Path, steps: int = 60) -> None:
    by_hand = compute_by_hand(mcap)
    assert sorted(metrics["agents"]) == sorted(by_hand) == ["sc01", "sc02"]
    for sid, xs in by_hand.items():
        n, p50, p99, mx = expected(xs)
        m = metrics["agents"][sid]
        assert n == steps and m["steps"] == n  # one stimulus a step: steps 0..59 of 10 s in 600 s
        assert m["p50_s"] == pytest.approx(p50, rel=1e-12) and m["p99_s"] == pytest.approx(p99, rel=1e-12)
        assert m["max_s"] == mx and 0.0 < p50 <= p99 <= mx


def test_lockstep_run_has_the_timing_section_with_no_wall_deadline(tmp_path) -> None:
    summary, page = run_and_report(tmp_path)
    m = summary["metrics"]["timing"]
    assert "Flight-software timing" in page and "no wall deadline" in page
    assert m["mode"] == "lockstep" and m["step_s"] == 10.0 and m["deadline_s"] is None
    assert m["p99_over_deadline"] == [] and not any(a["p99_over_deadline"] for a in m["agents"].values())
    check_against_mcap(m, tmp_path / "run" / "run.mcap")


def test_real_time_past_the_deadline_is_flagged(tmp_path) -> None:
    """Real time at speed 1e6: a 10 s step is due every 10 us of wall time, less than any agent's
    compute time per step, so every agent's p99 is over the deadline; the same recording read as at
    speed 1 (a 10 s deadline) flags nobody."""
    from swarmhil.dashboards.sections import SectionContext
    from swarmhil.dashboards.sections.timing import timing

    summary, page = run_and_report(tmp_path, "--mode", "realtime", "--speed", "1e6")
    m = summary["metrics"]["timing"]
    assert m["mode"] == "realtime" and m["deadline_s"] == pytest.approx(1e-5)
    assert m["p99_over_deadline"] == ["sc01", "sc02"] and "P99 OVER DEADLINE" in page
    check_against_mcap(m, tmp_path / "run" / "run.mcap")
    slow = {"run": {"mode": "realtime", "step_s": 10.0, "speed": 1.0}}
    again = timing(SectionContext(tmp_path, tmp_path / "run" / "run.mcap", tmp_path, {}, slow, None)).metrics
    assert again["deadline_s"] == 10.0 and again["p99_over_deadline"] == []
