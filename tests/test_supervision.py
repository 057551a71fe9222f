"""Supervision of a multi-process run (issue 17): no orphans, ever; SIGTERM like Ctrl-C; an agent
that dies at start-up fails the run at once.

The launcher (`swarmhil run`) is started as its own process; its children are found by the PIDs it
writes to run.json.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, read_mcap, sigint_default


def _wait_for(path: Path, timeout_s: float = 90.0) -> dict:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            time.sleep(0.05)
    raise TimeoutError(path)


def _wait_steps(out: Path, info: dict, n: int, timeout_s: float = 90.0) -> None:
    from swarmhil.bus import swarmhil_pb2 as pb
    from swarmhil.bus.acl import read_credential
    from swarmhil.bus.zenoh_bus import ZenohBus

    seen = threading.Event()
    bus = ZenohBus(info["router"], credential=read_credential(out / "secrets" / "launcher.cred"))
    bus.subscribe(f"swarm/{info['run']}/clock", lambda _k, p: pb.Tick.FromString(p).header.step >= n and seen.set())
    try:
        assert seen.wait(timeout_s), f"run did not reach step {n}"
    finally:
        bus.close()


def _alive(pid: int) -> bool:
    """Running (a zombie waiting for a reaper is not running)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _left(pids: dict[str, int], within_s: float) -> list[str]:
    t_end = time.monotonic() + within_s
    while time.monotonic() < t_end:
        left = [n for n, p in pids.items() if _alive(p)]
        if not left:
            return []
        time.sleep(0.1)
    return left


def _launch(out: Path, run_id: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "demo.toml"), "--out", str(out),
                             "--run-id", run_id, "--mode", "realtime", "--speed", "20", "--no-progress"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=sigint_default)


def test_sigkilled_launcher_leaves_no_child_and_a_readable_recording(tmp_path: Path) -> None:
    out = tmp_path / "sk"
    p = _launch(out, "sk")
    try:
        info = _wait_for(out / "run.json")
        _wait_steps(out, info, 5)
        p.kill()  # SIGKILL: no handler runs in the launcher, the router inside it is gone too
        p.communicate(timeout=30)
        left = _left(info["pids"], 10.0)
        assert not left, f"orphans: {left}"
    finally:
        for pid in json.loads((out / "run.json").read_text())["pids"].values() if (out / "run.json").exists() else []:
            if _alive(pid):
                import os

                os.kill(pid, signal.SIGKILL)  # this test's own run, by PID
    # the recorder was stopped by SIGTERM (parent-death signal) and closed its file
    msgs = read_mcap(out / "run.mcap")
    assert any(t == "truth" for t, *_ in msgs)  # topics are keys without swarm/<run>/


def test_sigterm_stops_the_run_like_ctrl_c(tmp_path: Path) -> None:
    out = tmp_path / "st"
    p = _launch(out, "st")
    info = _wait_for(out / "run.json")
    _wait_steps(out, info, 5)
    # real time: the recorder runs 10 nicer than the plant and agents (off the step's critical path)
    nice = {n: int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16]) for n, pid in info["pids"].items()}
    assert nice["recorder"] == min(19, nice["plant"] + 10) and nice["agent-sc01"] == nice["plant"], nice  # 19: the cap
    p.send_signal(signal.SIGTERM)
    _stdout, stderr = p.communicate(timeout=90)
    assert p.returncode == 143, stderr
    assert "SIGTERM" in stderr and "Traceback" not in stderr, stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] is True and 5 <= s["steps"] < 180, s
    assert not _left(info["pids"], 5.0)
    msgs = read_mcap(out / "run.mcap")
    assert [m.header.step for t, _l, _p, m in msgs if t == "truth"][:5] == list(range(5))


CRASH_PLUGIN = '''
import os, sys
if "agent" in sys.argv and "sc02" in sys.argv:
    print("sc02: flight software failed to load (test)", flush=True)
    os._exit(7)
'''


def test_agent_dying_at_start_up_fails_the_run_at_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from swarmhil.deploy.launcher import MultiProcessRun
    from swarmhil.deploy.scenario import load_scenario

    (tmp_path / "crash_sc02_plugin.py").write_text(CRASH_PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    scen = tmp_path / "crash.toml"
    scen.write_text((SCENARIOS / "demo.toml").read_text().replace('name = "demo"', 'name = "crash"\nplugins = ["crash_sc02_plugin"]', 1))
    out = tmp_path / "out"
    t0 = time.monotonic()
    res = MultiProcessRun(str(scen), load_scenario(scen), out, "crash", progress=False).execute()
    wall = time.monotonic() - t0
    assert res.exit_code == 1
    assert "agent-sc02" in res.reason and "start-up" in res.reason and "failed to load (test)" in res.reason, res.reason
    assert wall < 60, wall  # not the plant's 600 s wait
    assert not _left(res.pids, 5.0)
    s = json.loads((out / "summary.json").read_text())
    assert "agent-sc02" in s["failure"]


def test_sigkilled_router_stops_every_process_and_leaves_a_readable_recording(tmp_path: Path) -> None:
    """The router is its own process: SIGKILL it and every child (plant, agents, recorder) notices
    its session has lost the router and stops (deploy/proc.py ROUTER_GRACE_S); the launcher reports
    the failure; the recorder closed its MCAP."""
    import os

    out = tmp_path / "rk"
    p = _launch(out, "rk")
    try:
        info = _wait_for(out / "run.json")
        assert set(info["pids"]) >= {"router", "plant", "recorder"} and len(set(info["pids"].values())) == len(info["pids"])
        _wait_steps(out, info, 5)
        os.kill(info["pids"]["router"], signal.SIGKILL)
        _stdout, stderr = p.communicate(timeout=90)
        assert p.returncode == 1 and "router" in stderr and "Traceback" not in stderr, stderr
        left = _left(info["pids"], 10.0)
        assert not left, f"orphans: {left}"
    finally:
        if p.poll() is None:
            p.kill()
        for pid in json.loads((out / "run.json").read_text())["pids"].values() if (out / "run.json").exists() else []:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)  # this test's own run, by PID
    s = json.loads((out / "summary.json").read_text())
    assert "router" in s["failure"]
    steps = [m.header.step for t, _l, _p, m in read_mcap(out / "run.mcap") if t == "truth"]
    assert steps[:5] == list(range(5))


SIGNAL_ON_ANOTHER_THREAD = '''
import signal, sys, threading, time
{setup}
def other():
    time.sleep(0.3)
    signal.pthread_kill(threading.get_ident(), signal.SIGTERM)  # the kernel may pick this thread
    time.sleep(30)
threading.Thread(target=other, daemon=True).start()
t0 = time.monotonic()
stop.wait()
print(f"stopped {{time.monotonic() - t0:.2f}}", flush=True)
'''


@pytest.mark.parametrize("setup, stops", [
    ("from swarmhil.deploy.stopping import stop_on_signals\nstop = stop_on_signals(signal.SIGTERM)", True),
    # what the children did before: an untimed Event.wait() in the main thread is never woken
    ("stop = threading.Event()\nsignal.signal(signal.SIGTERM, lambda *_: stop.set())", False),
])
def test_sigterm_taken_by_another_thread_still_stops_the_main_thread(setup: str, stops: bool) -> None:
    """The kernel hands a process-directed SIGTERM (the launcher's, or PR_SET_PDEATHSIG) to any thread;
    the child must stop anyway (deploy/stopping.py). Once in about a dozen SIGKILLed-launcher runs an
    agent stayed until its 8 s router watchdog: this is that case made deterministic."""
    p = subprocess.Popen([sys.executable, "-c", SIGNAL_ON_ANOTHER_THREAD.format(setup=setup)], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = p.communicate(timeout=5)
        assert stops and p.returncode == 0 and out.startswith("stopped"), (out, err)
        assert float(out.split()[1]) < 2.0, out
    except subprocess.TimeoutExpired:
        p.kill()  # this test's own child, by its Popen
        p.communicate()
        assert not stops, "the main thread never woke up"
