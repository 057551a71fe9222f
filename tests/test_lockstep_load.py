"""Lockstep does not decide on wall time (issue 17): a slow live agent is waited for, a stall is
reported and dropped only after `[supervision].stall_timeout_s`, and CPU load changes nothing.

The slow agent is made slow by a scenario plugin (imported by every process) that sleeps inside
one agent's step: the process and its liveliness token stay up, it only answers late. The plant's
old rule (5 s timeout, 3 misses = dead) held that agent's previous command instead.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import SCENARIOS, read_mcap
from swarmhil.deploy.launcher import MultiProcessRun, run_in_process
from swarmhil.deploy.scenario import load_scenario

SLOW_PLUGIN = '''
import sys, time
if sys.argv[1:2] == ["agent"] and "sc02" in sys.argv:
    import swarmhil.agent.node as _n
    _handle = _n.AgentNode.handle
    def handle(self, stim):
        if int(stim.header.step) == 3:
            time.sleep({sleep_s})  # alive (token up), only slow
        return _handle(self, stim)
    _n.AgentNode.handle = handle
'''


def _slow_scenario(tmp: Path, monkeypatch: pytest.MonkeyPatch, sleep_s: float, extra: str = "") -> Path:
    mod = f"slow_sc02_{str(sleep_s).replace('.', '_')}"
    (tmp / f"{mod}.py").write_text(SLOW_PLUGIN.replace("{sleep_s}", str(sleep_s)))
    monkeypatch.syspath_prepend(str(tmp))
    monkeypatch.setenv("PYTHONPATH", str(tmp))
    scen = tmp / f"{mod}.toml"
    text = (SCENARIOS / "demo.toml").read_text().replace('name = "demo"', f'name = "slow"\nplugins = ["{mod}"]', 1)
    scen.write_text(text.replace("duration_s = 1800.0", "duration_s = 100.0") + extra)
    return scen


def _raw(path: Path, topic_prefixes: tuple[str, ...]) -> dict[str, list[bytes]]:
    from mcap.reader import make_reader

    out: dict[str, list[bytes]] = {}
    with open(path, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages():
            if ch.topic.startswith(topic_prefixes) and not ch.topic.endswith("/sense/rel"):
                out.setdefault(ch.topic, []).append(m.data)
    return out


def _events(path: Path) -> list:
    return [m for t, _l, _p, m in read_mcap(path) if t == "event"]


def test_a_slow_live_agent_is_waited_for(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """sc02 answers step 3 after 7 s (longer than the old 5 s lockstep timeout): the plant waits,
    nothing is missed, and the truth is byte-identical to the in-process run."""
    scen = _slow_scenario(tmp_path, monkeypatch, 7.0)
    sc = load_scenario(scen)
    res = MultiProcessRun(str(scen), sc, tmp_path / "mp", "slow", progress=False).execute()
    assert res.exit_code == 0, res.reason
    assert res.summary["dead_agents"] == {} and res.summary["missed_deadlines"] == {}, res.summary
    assert not [e for e in _events(tmp_path / "mp" / "run.mcap") if e.kind in ("deadline_missed", "lockstep_stall")]
    run_in_process(sc, tmp_path / "ip", "slow")
    mp = _raw(tmp_path / "mp" / "run.mcap", ("truth",))["truth"]
    assert len(mp) == 11 and mp == _raw(tmp_path / "ip" / "run.mcap", ("truth",))["truth"]


def test_a_stall_is_an_error_event_after_the_stall_timeout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """With [supervision].stall_timeout_s = 2, sc02 sleeping 8 s in step 3 is a stall: one error
    event `lockstep_stall`, sc02 dropped (dead, reason the stall), the run completes."""
    scen = _slow_scenario(tmp_path, monkeypatch, 8.0, "\n[supervision]\nstall_timeout_s = 2.0\n")
    sc = load_scenario(scen)
    assert sc.stall_timeout_s == 2.0
    res = MultiProcessRun(str(scen), sc, tmp_path / "mp", "stall", progress=False).execute()
    assert res.exit_code == 0, res.reason
    assert res.summary["steps"] == 10
    assert list(res.summary["dead_agents"]) == ["sc02"] and res.summary["dead_agents"]["sc02"]["step"] == 3
    assert "stall" in res.summary["dead_agents"]["sc02"]["reason"]
    ev = _events(tmp_path / "mp" / "run.mcap")
    stalls = [e for e in ev if e.kind == "lockstep_stall"]
    assert len(stalls) == 1 and stalls[0].header.step == 3 and "agent-sc02" not in stalls[0].detail
    assert "sc02" in stalls[0].detail
    assert [e.subject for e in ev if e.kind == "agent_dead"] == ["sc02"]


# A camera scenario with the link channel and beacons: 4 agents render and navigate every step.
LOAD_SCENARIO_EXTRA = """
[link]
range_m = 1000.0
loss_probability = 0.02
bitrate_bps = 9600.0
queue_packets = 8
occultation = true
stats_period_s = 60.0

[beacon]
period_s = 30.0
include_estimates = true
"""


def _burners(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"], stdin=subprocess.DEVNULL) for _ in range(n)]


def lockstep_quiet_and_loaded(tmp_path: Path) -> dict:
    """The same lockstep run of a camera + link scenario, undisturbed and beside 3 CPU burners per
    core: each run's summary, and the raw truth, command and ISL-delivery messages of each. Also
    the bench source of docs/reliability.md's figures (claims/reliability.py)."""
    src = (SCENARIOS / "sabatini-20-camera-filter.toml").read_text()
    scen = tmp_path / "cam-link.toml"
    scen.write_text(src.replace('name = "sabatini-20-camera-filter"', 'name = "cam-link"')
                    .replace("duration_s = 86400.0", "duration_s = 200.0").replace("count = 20", "count = 4")
                    + LOAD_SCENARIO_EXTRA)
    sc = load_scenario(scen)
    assert sc.sensing["kind"] == "scene" and "link" in sc.sections and len(sc.ids) == 4
    out: dict = {}
    for case in ("quiet", "loaded"):
        load_start = os.getloadavg()[0]
        burners = _burners(3 * (os.cpu_count() or 2)) if case == "loaded" else []
        try:
            res = MultiProcessRun(str(scen), sc, tmp_path / case, "cam-link", progress=False).execute()
        finally:
            for b in burners:
                os.kill(b.pid, signal.SIGKILL)  # our own burners, by PID
                b.wait()
        assert res.exit_code == 0, res.reason
        out[case] = {"summary": res.summary, "raw": _raw(tmp_path / case / "run.mcap", ("truth", "sc/", "isl/rx/")),
                     "burners": len(burners), "load_start": load_start, "load_end": os.getloadavg()[0]}
        print(f"\n{case}: {res.summary['wall_s']:.0f} s wall, {json.dumps(res.summary['channel']['totals'])}")
    return out


def compared_topics(raw: dict[str, list[bytes]]) -> list[str]:
    """What must be byte-identical: the truth, each agent's commands, the ISL deliveries."""
    return ["truth", *[t for t in raw if t.endswith("/act")], *[t for t in raw if t.startswith("isl/rx/")]]


@pytest.mark.system
def test_lockstep_under_cpu_load_is_bit_identical(tmp_path: Path) -> None:
    """The same lockstep run of a camera + link scenario, undisturbed and beside 3 CPU burners per
    core, gives byte-identical truth, commands and link deliveries."""
    runs = lockstep_quiet_and_loaded(tmp_path)
    for case in ("quiet", "loaded"):
        s = runs[case]["summary"]
        assert s["dead_agents"] == {} and s["missed_deadlines"] == {}, s
        assert s["channel"]["stalls"] == 0, s["channel"]
    quiet, loaded = runs["quiet"]["raw"], runs["loaded"]["raw"]
    assert len(quiet["truth"]) == 21
    acts = [t for t in quiet if t.endswith("/act")]
    rx = [t for t in quiet if t.startswith("isl/rx/")]
    assert len(acts) == 4 and rx and sum(len(quiet[t]) for t in rx) > 0
    for topic in compared_topics(quiet):
        assert loaded.get(topic) == quiet[topic], topic
