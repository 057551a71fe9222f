"""The backbone for real: agent processes, plant and recorder over Zenoh on loopback.

Recordings are read back with the standard `mcap` + `mcap-protobuf-support` readers only.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS, read_mcap, sigint_default
from deploy.launcher import MultiProcessRun, run_in_process
from deploy.scenario import load_scenario


def _mp(tmp: Path, scenario: str, run_id: str, **ov) -> tuple[MultiProcessRun, Path]:
    path = SCENARIOS / scenario
    sc = load_scenario(path).with_overrides(**ov)
    out = tmp / run_id
    return MultiProcessRun(str(path), sc, out, run_id, progress=False,
                           overrides={"duration": ov.get("duration_s"), "mode": ov.get("mode"),
                                      "speed": ov.get("speed")}), out


def _raw_truth(path: Path) -> list[bytes]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [m.data for _s, ch, m in make_reader(f).iter_messages(topics=None) if ch.topic.endswith("/truth")]


def test_drift20_multiprocess_recording(tmp_path: Path) -> None:
    """20 agent processes, each its own PID; a truth every step and every agent's command every step."""
    mp, out = _mp(tmp_path, "drift-20.toml", "d20", duration_s=200.0)
    res = mp.execute()
    assert res.exit_code == 0, res.reason
    pids = json.loads((out / "run.json").read_text())["pids"]
    agent_pids = {n: p for n, p in pids.items() if n.startswith("agent-")}
    assert len(agent_pids) == 20 and len(set(pids.values())) == len(pids)
    assert all(code == 0 for code in res.summary["exit_codes"].values()), res.summary["exit_codes"]
    msgs = read_mcap(out / "run.mcap")
    steps = res.summary["steps"]
    assert steps == 20
    truth = [m for t, _l, _p, m in msgs if t == "swarm/d20/truth"]
    assert [m.header.step for m in truth] == list(range(steps + 1))
    assert all(len(m.bodies) == 20 for m in truth)
    acts = Counter(t for t, *_ in msgs if t.endswith("/act"))
    assert set(acts) == {f"swarm/d20/sc/sc{i:02d}/act" for i in range(1, 21)}
    assert set(acts.values()) == {steps}
    for topic, _log, pub, m in msgs:
        assert topic.startswith("swarm/d20/")
        if hasattr(m, "header") and m.header.run:
            assert pub == round(m.header.t * 1e9)
    s = json.loads((out / "summary.json").read_text())
    for field in ("run", "scenario", "mode", "agents", "steps", "step_s", "duration_s", "wall_s", "reference_orbit",
                  "delta_v_total_mps", "delta_v_mps", "dead_agents", "rejected_packets"):
        assert field in s, field
    assert s["delta_v_total_mps"] == 0.0 and s["rejected_packets"] == 0 and s["agents"] == 20


def test_lockstep_is_deterministic_and_matches_in_process(tmp_path: Path) -> None:
    """Two multi-process lockstep runs and the in-process run give byte-identical truth."""
    runs = []
    for i in range(2):
        mp, out = _mp(tmp_path / f"m{i}", "demo.toml", "det", duration_s=400.0)
        assert mp.execute().exit_code == 0
        runs.append(_raw_truth(out / "run.mcap"))
    sc = load_scenario(SCENARIOS / "demo.toml").with_overrides(duration_s=400.0)
    run_in_process(sc, tmp_path / "inproc", "det")
    runs.append(_raw_truth(tmp_path / "inproc" / "run.mcap"))
    assert len(runs[0]) == 41
    assert runs[0] == runs[1] == runs[2]
    # the closed loop really acted: some command is non-zero
    from bus import swarmhil_pb2 as pb

    last = pb.Truth.FromString(runs[0][-1])
    assert sum(b.delta_v_mps for b in last.bodies) > 0


def _wait_for(path: Path, timeout_s: float = 60.0) -> dict:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            time.sleep(0.05)
    raise TimeoutError(path)


def _wait_steps(router: str, run: str, n: int, timeout_s: float = 60.0, out: Path | None = None) -> None:
    from bus.acl import read_credential
    from bus.zenoh_bus import ZenohBus

    seen = threading.Event()
    cred = out / "secrets" / "launcher.cred" if out is not None else None  # the run's router wants one
    bus = ZenohBus(router, credential=read_credential(cred) if cred is not None and cred.exists() else None)
    from bus import swarmhil_pb2 as pb

    bus.subscribe(f"swarm/{run}/clock", lambda k, p: pb.Tick.FromString(p).header.step >= n and seen.set())
    try:
        assert seen.wait(timeout_s), f"run did not reach step {n}"
    finally:
        bus.close()


def test_sigkilled_agent_leaves_run_alive_and_recorded(tmp_path: Path) -> None:
    mp, out = _mp(tmp_path, "demo.toml", "kill", duration_s=1000.0, mode="realtime", speed=100.0)
    th = threading.Thread(target=lambda: setattr(mp, "result", mp.execute()))
    th.start()
    info = _wait_for(out / "run.json")
    _wait_steps(info["router"], "kill", 20, out=out)
    os.kill(info["pids"]["agent-sc02"], signal.SIGKILL)
    th.join(120)
    res = mp.result
    assert res.exit_code == 0, res.reason
    s = res.summary
    assert list(s["dead_agents"]) == ["sc02"]
    assert s["steps"] == 100
    msgs = read_mcap(out / "run.mcap")
    events = [m for t, _l, _p, m in msgs if t == "swarm/kill/event" and m.kind == "agent_dead"]
    assert [e.subject for e in events] == ["sc02"]
    died = events[0].header.step
    truth = [m for t, _l, _p, m in msgs if t == "swarm/kill/truth"]
    sc02 = [next(b for b in m.bodies if b.id == "sc02") for m in truth]
    assert all(not b.alive for b in sc02[died + 1:]) and all(b.alive for b in sc02[: died - 1])
    assert all(b.accel_cmd_mps2.x == b.accel_cmd_mps2.y == b.accel_cmd_mps2.z == 0 for b in sc02[died + 2:])
    dv = [b.delta_v_mps for b in sc02]
    assert dv[-1] == dv[died + 1]  # it coasts
    # every other agent kept commanding to the end
    acts = Counter(t for t, *_ in msgs if t.endswith("/act"))
    assert acts["swarm/kill/sc/sc01/act"] >= 99 and acts["swarm/kill/sc/sc02/act"] < 30


def test_bad_payloads_on_command_keys_are_rejected_and_counted(tmp_path: Path) -> None:
    from bus import swarmhil_pb2 as pb
    from bus.zenoh_bus import open_client

    mp, out = _mp(tmp_path, "demo.toml", "bad", duration_s=1000.0, mode="realtime", speed=100.0)
    mp.secure = False  # the plant's own checks, behind an open router (the ACL: tests/test_security.py)
    th = threading.Thread(target=lambda: setattr(mp, "result", mp.execute()))
    th.start()
    info = _wait_for(out / "run.json")
    _wait_steps(info["router"], "bad", 5, out=out)
    rng = np.random.default_rng(0)
    s = open_client(info["router"])
    sent = 0
    nan_cmd = pb.ActuatorCommand(header=pb.Header(run="bad", source="sc01", step=10), accel_mps2=pb.Vector3(x=float("nan")))
    forged = pb.ActuatorCommand(header=pb.Header(run="bad", source="sc03", step=10), accel_mps2=pb.Vector3(x=1.0))
    other_run = pb.ActuatorCommand(header=pb.Header(run="zzz", source="sc01", step=10))
    for payload, key in [(nan_cmd.SerializeToString(), "sc01"), (forged.SerializeToString(), "sc01"),
                         (other_run.SerializeToString(), "sc01"), (b"\x0a\xff\xff\xff", "sc01"),
                         (forged.SerializeToString(), "sc99")] + [(rng.bytes(int(rng.integers(1, 200))), "sc04") for _ in range(20)]:
        s.put(f"swarm/bad/sc/{key}/act", payload)
        sent += 1
    s.close()
    th.join(120)
    res = mp.result
    assert res.exit_code == 0, res.reason
    summ = res.summary
    assert summ["steps"] == 100 and summ["dead_agents"] == {}
    # random bytes can happen to parse as a valid (empty) command for step 0 -> counted late, not applied
    assert summ["rejected_packets"] + summ["late_commands"] >= sent
    assert summ["rejected_packets"] >= 5
    msgs = read_mcap(out / "run.mcap")  # the standard reader decodes every message, garbage included
    assert sum(1 for t, *_ in msgs if t.endswith("/sc/sc99/act")) == 1


def test_mcap_repair_salvages_killed_recorder(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    code = f"""
import os, signal, sys
sys.path.insert(0, {str(ROOT)!r})
from bus.recorder import McapRecorder
from bus import swarmhil_pb2 as pb
r = McapRecorder({str(path)!r}, "k", chunk_size=4096)
for i in range(3000):
    t = pb.Tick(header=pb.Header(run="k", source="plant", step=i, t=10.0 * i), step_s=10.0)
    r.write("swarm/k/clock", t.SerializeToString())
os.kill(os.getpid(), signal.SIGKILL)
"""
    p = subprocess.run([sys.executable, "-c", code])
    assert p.returncode == -signal.SIGKILL
    from mcap.reader import make_reader

    with pytest.raises(Exception):
        with open(path, "rb") as f:
            list(make_reader(f).iter_messages())
    fixed = tmp_path / "fixed.mcap"
    r = subprocess.run([sys.executable, "-m", "deploy.cli", "mcap", "repair", str(path), str(fixed)],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    msgs = read_mcap(fixed)
    steps = [m.header.step for _t, _l, _p, m in msgs]
    assert steps == list(range(len(steps)))
    assert 3000 - len(steps) < 4096 // 20  # at most the open chunk (a Tick is > 20 B) is lost


def test_realtime_missed_deadlines_hold_the_previous_command(tmp_path: Path) -> None:
    """A frozen agent (SIGSTOP for 1 s) misses real-time deadlines: counted, command held, not dead."""
    mp, out = _mp(tmp_path, "demo.toml", "rt", duration_s=800.0, mode="realtime", speed=100.0)
    th = threading.Thread(target=lambda: setattr(mp, "result", mp.execute()))
    th.start()
    info = _wait_for(out / "run.json")
    _wait_steps(info["router"], "rt", 20, out=out)
    pid = info["pids"]["agent-sc03"]
    os.kill(pid, signal.SIGSTOP)
    time.sleep(1.0)
    os.kill(pid, signal.SIGCONT)
    th.join(120)
    res = mp.result
    assert res.exit_code == 0, res.reason
    s = res.summary
    assert s["dead_agents"] == {}
    assert s["missed_deadlines"].get("sc03", 0) >= 5
    msgs = read_mcap(out / "run.mcap")
    missed = [m.header.step for t, _l, _p, m in msgs if t == "swarm/rt/event" and m.kind == "deadline_missed" and m.subject == "sc03"]
    truth = {m.header.step: next(b for b in m.bodies if b.id == "sc03") for t, _l, _p, m in msgs if t == "swarm/rt/truth"}
    held = [k for k in missed if k + 1 in truth]
    assert held
    for k in held:  # the command applied over a missed step k (in truth k+1) equals the one over step k-1
        a, b = truth[k + 1].accel_cmd_mps2, truth[k].accel_cmd_mps2
        assert (a.x, a.y, a.z) == (b.x, b.y, b.z)


def test_ctrl_c_stops_the_run_cleanly(tmp_path: Path) -> None:
    """SIGINT to the launcher (Ctrl-C): every child stopped, a finished, readable MCAP, exit 130."""
    out = tmp_path / "cc"
    p = subprocess.Popen([sys.executable, "-m", "deploy.cli", "run", str(SCENARIOS / "demo.toml"), "--out", str(out),
                          "--run-id", "cc", "--mode", "realtime", "--speed", "20", "--no-progress"],
                         cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=sigint_default)
    info = _wait_for(out / "run.json")
    _wait_steps(info["router"], "cc", 5, out=out)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == 130, stderr
    assert "interrupted" in stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] is True, s
    assert 5 <= s.get("steps", -1) < 180, s
    for name, pid in info["pids"].items():  # every child is gone
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    msgs = read_mcap(out / "run.mcap")  # finished properly: the indexed reader opens it
    assert sum(1 for t, *_ in msgs if t == "swarm/cc/truth") >= 5
