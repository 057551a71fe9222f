"""Supervision that heals (issue 17): `[supervision] restart = "on-failure"` restarts a dead agent,
which rejoins cold at the plant's next step, up to `max_restarts`; an agent paused longer than its
Zenoh lease and resumed rejoins. Events `agent_restart` (launcher) and `agent_rejoin` (plant) are
recorded; no process is left (every PID ever started, run.json `all_pids`)."""
from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

import pytest

from conftest import SCENARIOS, read_mcap
from swarmhil.deploy.launcher import MultiProcessRun
from swarmhil.deploy.scenario import load_scenario
from test_supervision import _alive

CRASH_PLUGIN = '''
import os, sys
if sys.argv[1:2] == ["agent"] and "sc02" in sys.argv:
    import swarmhil.agent.node as _n
    _handle = _n.AgentNode.handle
    def handle(self, stim):
        if {when}:
            print(f"sc02: crash at step {{stim.header.step}} (test)", flush=True)
            os._exit(9)
        return _handle(self, stim)
    _n.AgentNode.handle = handle
'''


def _scenario(tmp: Path, monkeypatch: pytest.MonkeyPatch | None, name: str, plugin: str | None, extra: str,
              duration_s: float = 300.0) -> Path:
    text = (SCENARIOS / "demo.toml").read_text().replace("duration_s = 1800.0", f"duration_s = {duration_s}")
    if plugin is not None:
        (tmp / f"{name}_plugin.py").write_text(plugin)
        monkeypatch.syspath_prepend(str(tmp))
        monkeypatch.setenv("PYTHONPATH", str(tmp))
        text = text.replace('name = "demo"', f'name = "{name}"\nplugins = ["{name}_plugin"]', 1)
    else:
        text = text.replace('name = "demo"', f'name = "{name}"', 1)
    scen = tmp / f"{name}.toml"
    scen.write_text(text + extra)
    return scen


def _run(scen: Path, out: Path, run: str):  # type: ignore[no-untyped-def]
    """Real time at x10 (1 s a step): a restarted agent (a few seconds to start) rejoins mid-run."""
    sc = load_scenario(scen).with_overrides(mode="realtime", speed=10.0)
    return MultiProcessRun(str(scen), sc, out, run, progress=False, overrides={"mode": "realtime", "speed": 10.0})


SUPERVISED = '\n[supervision]\nrestart = "on-failure"\nmax_restarts = 2\n'


def _pause_agent(out: Path, run: str, at_step: int = 3, pause_s: float = 8.0) -> None:
    """SIGSTOP agent sc02 of the running run at `at_step` for `pause_s` (longer than its 5 s Zenoh
    lease), then SIGCONT."""
    from test_backbone_run import _Clock

    t_end = time.monotonic() + 120
    while not (out / "run.json").exists() and time.monotonic() < t_end:
        time.sleep(0.05)
    info = json.loads((out / "run.json").read_text())
    clock = _Clock(info["router"], run, out)
    try:
        clock.wait_step(at_step, 240)
        pid = info["pids"]["agent-sc02"]
        os.kill(pid, signal.SIGSTOP)
        time.sleep(pause_s)
        os.kill(pid, signal.SIGCONT)
    finally:
        clock.close()


@pytest.fixture(scope="module")
def realtime_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Any]]:
    """The three real-time runs of the tests below, flown at the same time: {run: (out, RunResult)}.
    Each is a run of its own (router on its own port, processes, recording); each takes about 30 s
    of wall time at x10 and little CPU (it waits on the clock), so together they take about as long
    as one. Every run has ended (and is joined) before a test reads it."""
    from test_backbone_run import _join, _start

    tmp = tmp_path_factory.mktemp("restart")
    with pytest.MonkeyPatch.context() as mp:  # the plugins' folder on the children's path until every run has ended
        scens = {"restart": _scenario(tmp, mp, "restart", CRASH_PLUGIN.format(when="int(stim.header.step) == 5"), SUPERVISED),
                 "maxrs": _scenario(tmp, mp, "maxrs", CRASH_PLUGIN.format(when="int(stim.header.step) >= 5"), SUPERVISED),
                 "pause": _scenario(tmp, None, "pause", None, "")}
        threads = {run: _start(_run(scen, tmp / run, run)) for run, scen in scens.items()}
        try:
            _pause_agent(tmp / "pause", "pause")
        finally:
            results = {run: (tmp / run, _join(th, 300.0)) for run, th in threads.items()}
    return results


def _no_process_left(out: Path) -> None:
    pids = [p for ps in json.loads((out / "run.json").read_text())["all_pids"].values() for p in ps]
    t_end = time.monotonic() + 10
    while time.monotonic() < t_end and any(_alive(p) for p in pids):
        time.sleep(0.1)
    assert not [p for p in pids if _alive(p)]


def _events(out: Path) -> list:
    return [m for t, _l, _p, m in read_mcap(out / "run.mcap") if t == "event"]


def test_a_crashed_agent_is_restarted_and_rejoins_cold(realtime_runs: dict[str, tuple[Path, Any]]) -> None:
    """sc02 crashes at step 5 (restart = "on-failure", max_restarts = 2)."""
    out, res = realtime_runs["restart"]
    assert res.exit_code == 0, res.reason
    s = res.summary
    assert s["restarts"] == {"agent-sc02": 1} and len(s["all_pids"]["agent-sc02"]) == 2
    assert s["dead_agents"] == {}  # alive again at the end
    assert len(s["rejoins"]) == 1 and s["rejoins"][0]["id"] == "sc02" and s["rejoins"][0]["dead_step"] in (5, 6)
    rejoin_step = s["rejoins"][0]["step"]
    ev = _events(out)
    assert [(e.kind, e.subject) for e in ev if e.kind in ("agent_dead", "agent_restart", "agent_rejoin")] == \
        [("agent_dead", "sc02"), ("agent_restart", "sc02"), ("agent_rejoin", "sc02")]
    assert [e.header.source for e in ev if e.kind == "agent_restart"] == ["launcher"]
    msgs = read_mcap(out / "run.mcap")
    acts = sorted(int(m.header.step) for t, _l, _p, m in msgs if t == "sc/sc02/act")
    assert acts[:5] == [0, 1, 2, 3, 4] and 5 not in acts
    assert acts[5:] == list(range(rejoin_step, 30))  # cold rejoin: every step from the rejoin on
    truth = [m for t, _l, _p, m in msgs if t == "truth"]
    alive = [next(b.alive for b in m.bodies if b.id == "sc02") for m in truth]
    dead_step = s["rejoins"][0]["dead_step"]
    assert alive[4] and alive[rejoin_step] and alive[-1] and rejoin_step > dead_step
    assert not any(alive[dead_step + 1:rejoin_step])  # coasting, dead, until it rejoined
    assert "crash at step 5 (test)" in (out / "logs" / "agent-sc02.log").read_text()  # the log is appended to
    _no_process_left(out)


def test_restarts_stop_at_max_restarts(realtime_runs: dict[str, tuple[Path, Any]]) -> None:
    """sc02 crashes at every step from 5 on (restart = "on-failure", max_restarts = 2)."""
    out, res = realtime_runs["maxrs"]
    assert res.exit_code == 0, res.reason
    assert res.summary["restarts"] == {"agent-sc02": 2} and len(res.summary["all_pids"]["agent-sc02"]) == 3
    assert list(res.summary["dead_agents"]) == ["sc02"]  # the third death is final
    kinds = [e.kind for e in _events(out) if e.subject == "sc02"]
    assert kinds.count("agent_dead") == 3 and kinds.count("agent_restart") == 2
    _no_process_left(out)


def test_a_paused_agent_rejoins_after_its_lease(realtime_runs: dict[str, tuple[Path, Any]]) -> None:
    """SIGSTOP an agent for 8 s at step 3 (its Zenoh lease is 5 s: declared dead), then SIGCONT: its
    client session reconnects, its liveliness token comes back, and the plant takes it back cold."""
    out, res = realtime_runs["pause"]
    s = res.summary
    assert res.exit_code == 0, res.reason
    assert s["restarts"] == {} and s["dead_agents"] == {}, s
    assert len(s["rejoins"]) == 1 and "liveliness" in s["rejoins"][0]["dead_reason"]
    assert s["rejoins"][0]["step"] < 28
    kinds = [e.kind for e in _events(out) if e.subject == "sc02"]
    assert "agent_dead" in kinds and "agent_rejoin" in kinds
    _no_process_left(out)


def test_a_stalled_agent_is_killed_and_restarted(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Alive but silent past `stall_timeout_s` (2 s; it sleeps 60 s in step 3): the plant drops it
    (lockstep_stall), and with restart = "on-failure" the launcher ends it by PID and restarts it."""
    from test_lockstep_load import SLOW_PLUGIN

    scen = _scenario(tmp_path, monkeypatch, "stallrs", SLOW_PLUGIN.replace("{sleep_s}", "60.0"),
                     '\n[supervision]\nstall_timeout_s = 2.0\nrestart = "on-failure"\n', duration_s=1800.0)
    out = tmp_path / "run"
    res = MultiProcessRun(str(scen), load_scenario(scen), out, "stallrs", progress=False).execute()
    assert res.exit_code == 0, res.reason
    assert res.summary["restarts"] == {"agent-sc02": 1}, res.summary
    kinds = [(e.kind, e.subject) for e in _events(out) if e.kind in ("lockstep_stall", "agent_dead", "agent_restart")]
    assert kinds[:3] == [("lockstep_stall", "plant"), ("agent_dead", "sc02"), ("agent_restart", "sc02")], kinds
    assert res.summary["wall_s"] < 55  # not the 60 s sleep
    _no_process_left(out)
