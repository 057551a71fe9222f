"""External flight software (issue 26, docs/hil.md): a spacecraft with `fsw = "external"` is flown by
a process the launcher does not start, here examples/external_fsw/fc.py, which imports nothing of
the project. Real processes over real Zenoh on loopback; recordings read with the standard readers.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, read_mcap
from swarmhil.deploy.scenario import ScenarioError, load_scenario, parse_scenario

SCENARIO = SCENARIOS / "hil-3.toml"
SWARMHIL = [sys.executable, "-m", "swarmhil.deploy.cli"]
FC = ROOT / "examples" / "external_fsw"


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except OSError:
        return False


def _started_pids(out: Path) -> list[int]:
    return [p for pids in json.loads((out / "run.json").read_text())["all_pids"].values() for p in pids]


def test_external_spacecraft_is_validated() -> None:
    sc = load_scenario(SCENARIO)
    from swarmhil.deploy.external import external_ids, join_timeout_s, plant_ready_timeout_s

    assert external_ids(sc) == ["sc02"] and join_timeout_s(sc, "sc02") == 300.0
    assert plant_ready_timeout_s(sc.with_overrides()) == 600.0
    assert sc.resolved()["spacecraft"][1]["fsw"] == "external"  # the recording says who flew it
    doc = tomllib.loads(SCENARIO.read_text())
    bad = json.loads(json.dumps(doc))
    bad["spacecraft"][1]["fsw"] = "elsewhere"
    with pytest.raises(ScenarioError, match=r"x.toml: \[\[spacecraft\]\]\[1\].fsw .*'builtin' or 'external'"):
        parse_scenario(bad, "x.toml")
    bad = json.loads(json.dumps(doc))
    bad["spacecraft"][1]["join_timeout_s"] = -5.0
    with pytest.raises(ScenarioError, match=r"\[\[spacecraft\]\]\[1\].join_timeout_s .*greater than 0"):
        parse_scenario(bad, "x.toml")
    builtin = load_scenario(SCENARIO, ["spacecraft.1.fsw=builtin"])  # the same scenario, flown built in
    assert external_ids(builtin) == []
    long = json.loads(json.dumps(doc))
    long["spacecraft"][1]["join_timeout_s"] = 3600.0
    assert plant_ready_timeout_s(parse_scenario(long, "x.toml")) == 3660.0  # the plant outwaits the launcher


def test_in_process_run_refuses_an_external_spacecraft(tmp_path: Path) -> None:
    r = subprocess.run([*SWARMHIL, "run", str(SCENARIO), "--in-process", "--out", str(tmp_path / "r")],
                       capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=120)
    assert r.returncode == 2, r
    assert r.stderr.strip().count("\n") == 0 and "sc02 fly external flight software" in r.stderr, r.stderr


def test_join_listen_is_checked_before_anything_starts(tmp_path: Path) -> None:
    """--join-listen (the router's extra endpoint for another host): the run's protocol, an explicit
    address and port, and a scenario with an external spacecraft; else one line, exit 2."""
    cases = [(SCENARIO, ["--tls", "--join-listen", "tcp/10.213.1.1:7447"], "must be tls/ADDRESS:PORT"),
             (SCENARIO, ["--join-listen", "tcp/0.0.0.0:7447"], "a wildcard address"),
             (SCENARIO, ["--join-listen", "tcp/10.213.1.1"], "must be tcp/ADDRESS:PORT"),
             (SCENARIOS / "demo.toml", ["--join-listen", "tcp/10.213.1.1:7447"], "no spacecraft with fsw = \"external\"")]
    from click.testing import CliRunner

    from swarmhil.deploy.cli import main

    for i, (scenario, args, why) in enumerate(cases):
        r = CliRunner().invoke(main, ["run", str(scenario), "--out", str(tmp_path / str(i)), *args])
        assert r.exit_code == 2 and r.stderr.count("\n") == 1 and why in r.stderr, (args, r.stderr)
        assert not (tmp_path / str(i) / "run.json").exists()


def test_join_timeout_is_one_line_and_leaves_nothing_running(tmp_path: Path) -> None:
    """Nobody joins: the launcher prints where the kit is and what it waits for, then, after the
    join timeout, one line naming the spacecraft and the endpoint; exit 1; every process it
    started is gone."""
    out = tmp_path / "run"
    r = subprocess.run([*SWARMHIL, "run", str(SCENARIO), "--out", str(out), "--run-id", "jt", "--no-progress",
                        "--set", "spacecraft.1.join_timeout_s=2"],
                       capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=180)
    assert r.returncode == 1, (r.stdout, r.stderr)
    router = json.loads((out / "run.json").read_text())["router"]
    assert r.stdout.splitlines() == [
        f"waiting up to 2 s for the external flight software of sc02 to join at {router} (liveliness token "
        f"swarm/jt/alive/agent-sc02); its join kit: {out}/external/sc02/join.json"], r.stdout
    assert r.stderr.splitlines() == [
        f"error: external flight software of spacecraft sc02 did not join within 2 s: no liveliness token "
        f"swarm/jt/alive/agent-sc02 at {router}"], r.stderr
    pids = _started_pids(out)
    assert len(pids) == 5 and not [p for p in pids if _alive(p)]  # router, recorder, plant, sc01, sc03
    kit = out / "external" / "sc02"
    assert sorted(p.name for p in kit.iterdir()) == ["agent-sc02.cred", "join.json", "keys.json", "swarmhil.proto"]
    assert (kit / "swarmhil.proto").read_bytes() == (ROOT / "bus" / "swarmhil.proto").read_bytes()
    assert all(p.stat().st_mode & 0o077 == 0 for p in [kit, *kit.iterdir()])  # it holds a secret
    doc = json.loads((kit / "join.json").read_text())
    assert doc["router"] == [router] and doc["run"] == "jt" and doc["process"] == "agent-sc02"
    assert doc["keys"]["act"] == "swarm/jt/sc/sc02/act" and doc["message_types"]["sense"] == "swarmhil.v1.RelStimulus"
    assert doc["zenoh"]["transport/auth/usrpwd/password"] == (kit / "agent-sc02.cred").read_text().strip().split(":")[1]
    assert doc["timing"]["deadline"]["mode"] == "lockstep" and doc["agent"]["controller"] == "drift-null"


PROJECT_PACKAGES = {"agent", "bus", "claims", "dashboards", "deploy", "link", "missions", "plant", "swarmhil"}


@pytest.fixture(scope="module")
def fc_build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference flight computer's own build step (examples/external_fsw/build.sh): protobuf
    code generated from bus/swarmhil.proto, into a directory of the test's."""
    build = tmp_path_factory.mktemp("fc-build")
    r = subprocess.run([str(FC / "build.sh"), str(ROOT / "bus" / "swarmhil.proto"), str(build)], capture_output=True,
                       text=True, env={**os.environ, "PYTHON": sys.executable}, timeout=120)
    assert r.returncode == 0 and (build / "swarmhil_pb2.py").is_file(), r.stderr
    return build


class Flight:
    """`swarmhil run` of a scenario with an external spacecraft, and the reference flight computer
    started from its join kit once the launcher has written it."""

    def __init__(self, out: Path, run_id: str, build: Path, args: list[str] = (), fc_args: list[str] = ()) -> None:
        self.out = out
        self.launcher = subprocess.Popen([*SWARMHIL, "run", str(SCENARIO), "--out", str(out), "--run-id", run_id,
                                          "--no-progress", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                         text=True, env=_env(), cwd=ROOT)
        self.kit = out / "external" / "sc02"
        t_end = time.monotonic() + 120
        while not (self.kit / "join.json").exists():
            assert self.launcher.poll() is None, self.launcher.communicate()
            assert time.monotonic() < t_end, "no join kit after 120 s"
            time.sleep(0.1)
        self.audit = out.parent / f"{run_id}-fc-modules.json"
        # the flight computer runs outside the repository with the bare interpreter: nothing of
        # the project on its path but what the editable install adds (the audit shows it took none)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        self.fc = subprocess.Popen([sys.executable, str(FC / "fc.py"), str(self.kit), "--build", str(build),
                                    "--audit", str(self.audit), *fc_args], stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True, env=env, cwd=out.parent)

    def finish(self, timeout_s: float = 300.0) -> tuple[int, str, str, str]:
        """(launcher exit code, its stdout, its stderr, the flight computer's output)."""
        out, err = self.launcher.communicate(timeout=timeout_s)
        fc_out, _ = self.fc.communicate(timeout=60)
        return self.launcher.returncode, out, err, fc_out


def _forge_commands(kit: Path, stop: threading.Event, done: dict[str, int]) -> None:
    """With the kit's credential, until stopped: full-thrust commands for the other spacecraft every
    step (were they let through, the plant would take them: right run, source = the key's id), and
    on sc02's own key, every 0.1 s, a command naming another run, one naming another source and a
    payload that does not parse. `done` counts what was put, and `connected` whether the session
    reached the run's router (the test then knows the forger did connect and publish)."""
    import zenoh

    from swarmhil.bus import swarmhil_pb2 as pb

    doc = json.loads((kit / "join.json").read_text())
    cfg = zenoh.Config()
    for key, value in doc["zenoh"].items():
        cfg.insert_json5(key, json.dumps(value))
    run = doc["run"]
    cmd = lambda run_, src, step: pb.ActuatorCommand(  # noqa: E731
        header=pb.Header(run=run_, source=src, step=step, t=step * 10.0), accel_mps2=pb.Vector3(x=1e-3, y=1e-3, z=1e-3),
        controller="rogue").SerializeToString()
    with zenoh.open(cfg) as session:
        done["connected"] = int(bool(list(session.info.routers_zid())))
        pubs = {sid: session.declare_publisher(f"swarm/{run}/sc/{sid}/act") for sid in ("sc01", "sc03")}
        own = session.declare_publisher(doc["keys"]["act"])
        last_own = 0.0
        while not stop.wait(0.02):
            for step in range(100):
                for sid, pub in pubs.items():
                    pub.put(cmd(run, sid, step))
            done["other_keys"] = done.get("other_keys", 0) + 200
            if time.monotonic() - last_own >= 0.1:
                last_own = time.monotonic()
                own.put(cmd("another-run", "sc02", 0))
                own.put(cmd(run, "sc01", 0))
                own.put(b"\xff\xff not a command")
                done["own_key"] = done.get("own_key", 0) + 1


def _truth(path: Path) -> list[bytes]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [m.data for _s, ch, m in make_reader(f).iter_messages() if ch.topic == "truth"]


def _acts(path: Path, sid: str) -> list:
    """The commands recorded on sid's act key as ActuatorCommands (rejected ones are RejectedSamples)."""
    return [m for t, _l, _p, m in read_mcap(path) if t == f"sc/{sid}/act"
            and m.DESCRIPTOR.full_name == "swarmhil.v1.ActuatorCommand"]


def test_external_flight_computer_flies_bit_identical_to_the_built_in(tmp_path: Path, fc_build: Path) -> None:
    """sc02 of hil-3 flown by examples/external_fsw/fc.py (imports nothing of the project) in a
    multi-process lockstep run: the truth is byte for byte the one of the same run with sc02's
    built-in drift-null agent, and sc02's commands are non-zero and follow its stimuli."""
    from swarmhil.deploy.launcher import MultiProcessRun

    steps = ["--duration", "1000"]
    flight = Flight(tmp_path / "ext", "hil1", fc_build, steps)
    stop = threading.Event()
    forged: dict[str, int] = {}
    rogue = threading.Thread(target=_forge_commands, args=(flight.kit, stop, forged), daemon=True)
    rogue.start()  # sc02's credential put on sc01's and sc03's keys: the router's ACL drops it all
    code, out, err, fc_out = flight.finish()
    stop.set()
    rogue.join(10)
    assert code == 0, (out, err, fc_out)
    # the forger did reach the router and publish, on the others' keys and on its own
    assert forged.get("connected") == 1 and forged.get("other_keys", 0) >= 1000 and forged.get("own_key", 0) >= 2, forged
    assert "fc: answered 100 stimuli" in fc_out, fc_out
    modules = set(json.loads(flight.audit.read_text()))
    assert {"zenoh", "numpy", "swarmhil_pb2"} <= modules and not modules & PROJECT_PACKAGES, modules & PROJECT_PACKAGES
    s = json.loads((tmp_path / "ext" / "summary.json").read_text())
    assert s["steps"] == 100 and not s["dead_agents"] and not s["missed_deadlines"], s
    # nothing forged on sc01's or sc03's keys reached the plant (the ACL dropped it); what it forged on
    # its own key did, and was rejected: one Event each with the reason and the claimed source, the
    # commands recorded as RejectedSample (never as ActuatorCommand), the garbage with its step
    msgs = read_mcap(tmp_path / "ext" / "run.mcap")
    assert s["rejected_packets_by_key"] == {"swarm/hil1/sc/sc02/act": s["rejected_packets"]}, s
    events = [m for t, _l, _p, m in msgs if t == "event" and m.kind == "rejected_command"]
    # (rejections after the recorder stopped, at the run's end, are counted but not recorded)
    assert 3 <= len(events) <= s["rejected_packets"] and {e.subject for e in events} == {"sc02"}
    details = [json.loads(e.detail) for e in events]
    assert {(d["claimed_source"], d["claimed_run"]) for d in details} == {("sc02", "another-run"), ("sc01", "hil1"), ("", "")}
    assert any("header.run 'another-run' is not 'hil1'" in d["reason"] for d in details)
    assert any("header.source 'sc01' does not match key id 'sc02'" in d["reason"] for d in details)
    on_key = [m for t, _l, _p, m in msgs if t == "sc/sc02/act"]
    kinds = {m.DESCRIPTOR.full_name for m in on_key}
    assert kinds == {"swarmhil.v1.ActuatorCommand", "swarmhil.v1.RejectedSample", "swarmhil.v1.UndecodableSample"}
    rejected = [m for m in on_key if m.DESCRIPTOR.full_name == "swarmhil.v1.RejectedSample"]
    assert {(m.claimed_source, m.claimed_run) for m in rejected} == {("sc02", "another-run"), ("sc01", "hil1")}
    undecodable = [m for m in on_key if m.DESCRIPTOR.full_name == "swarmhil.v1.UndecodableSample"]
    assert undecodable and all(m.payload == b"\xff\xff not a command" for m in undecodable)
    wrapped = [m.header for m in rejected + undecodable]
    assert all(h.source == "recorder" and 0 <= h.step <= 100 and h.t == h.step * 10.0 for h in wrapped)
    assert max(h.step for h in wrapped) > 0, [h.step for h in wrapped]   # the step each arrived in, not 0
    assert s["external"]["sc02"]["joined_after_s"] is not None and "agent-sc02" not in s["pids"]

    sc = load_scenario(SCENARIO, ["spacecraft.1.fsw=builtin"]).with_overrides(duration_s=1000.0)
    ref = MultiProcessRun(str(SCENARIO), sc, tmp_path / "builtin", "hil1", progress=False,
                          overrides={"duration": 1000.0}).execute()
    assert ref.exit_code == 0, ref.reason
    ext_mcap, ref_mcap = tmp_path / "ext" / "run.mcap", tmp_path / "builtin" / "run.mcap"
    truth = _truth(ext_mcap)
    assert len(truth) == 101 and truth == _truth(ref_mcap)  # bit for bit
    ext_acts, ref_acts = _acts(ext_mcap, "sc02"), _acts(ref_mcap, "sc02")
    assert {a.controller for a in ext_acts} == {a.controller for a in ref_acts} == {"drift-null"}
    tm = [m.controller for t, _l, _p, m in read_mcap(ext_mcap) if t == "sc/sc02/tm"]
    assert len(tm) == 100 and set(tm) == {"drift-null/external"}  # the recording says who flew it
    uy = [a.accel_mps2.y for a in ext_acts]
    assert uy == [a.accel_mps2.y for a in ref_acts] and [a.header.step for a in ext_acts] == list(range(100))
    assert all(u != 0.0 for u in uy) and len(set(uy)) > 50  # a law of its stimuli, not the null controller
    assert s["delta_v_mps"]["sc02"] > 0 and s["delta_v_mps"] == ref.summary["delta_v_mps"]
    # and the built-in flight software re-flown on what the external one received commands the same
    r = subprocess.run([*SWARMHIL, "refly", str(tmp_path / "ext"), "--agent", "sc02", "--exit-code"],
                       capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("sc02: identical over 100 steps"), (r.stdout, r.stderr)


WARM_START = """
import runpy, sys
import numpy, zenoh, google.protobuf.message  # fc.py's imports, before the test says join
print("ready", flush=True)
sys.stdin.readline()
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""
"""`python -c WARM_START fc.py ARGS...`: the reference flight computer, run once a line comes on stdin."""


def test_killed_external_flight_computer_coasts_and_the_run_completes(tmp_path: Path, fc_build: Path) -> None:
    """SIGKILL the external flight computer (its PID) mid-run: the plant marks sc02 dead, it coasts
    (no command, zero applied acceleration), the event is in the MCAP and the run completes. A new
    flight computer started from the same kit rejoins cold (event agent_rejoin) and flies again."""
    import signal

    flight = Flight(tmp_path / "kill", "hil2", fc_build, fc_args=["--print-steps"])
    # the second computer is started now and waits, its imports done, for the word to join: the
    # 270 lockstep steps after the kill take a few seconds, and an interpreter starting only then
    # could miss them all on a loaded machine (the run would end with sc02 dead)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    second = subprocess.Popen([sys.executable, "-c", WARM_START, str(FC / "fc.py"), str(flight.kit), "--build", str(fc_build)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    assert second.stdout.readline() == "ready\n"
    for line in flight.fc.stdout:  # answered stimuli, one line each
        if line.startswith("step 30 "):
            break
    os.kill(flight.fc.pid, signal.SIGKILL)
    assert flight.fc.wait(30) == -signal.SIGKILL
    second.stdin.write("join\n")
    second.stdin.flush()
    code, out, err, _fc = flight.finish()
    second_out, _ = second.communicate(timeout=60)
    assert code == 0, (out, err)
    s = json.loads((tmp_path / "kill" / "summary.json").read_text())
    assert s["steps"] == 300 and not s["dead_agents"], s["dead_agents"]  # back alive at the end
    (rejoin,) = s["rejoins"]
    d, r = rejoin["dead_step"], rejoin["step"]
    assert rejoin["id"] == "sc02" and rejoin["dead_reason"] == "liveliness token disappeared" and 30 <= d < r < 300, rejoin
    msgs = read_mcap(tmp_path / "kill" / "run.mcap")
    events = [(m.kind, m.subject, m.header.step) for t, _l, _p, m in msgs
              if t == "event" and m.kind in ("agent_dead", "agent_rejoin")]
    assert events == [("agent_dead", "sc02", d), ("agent_rejoin", "sc02", r)]
    truth = [m for t, _l, _p, m in msgs if t == "truth"]
    assert len(truth) == 301 and truth[-1].header.step == 300  # the run completed
    sc02 = [next(b for b in m.bodies if b.id == "sc02") for m in truth]
    assert all(b.alive and b.accel_cmd_mps2.y != 0.0 for b in sc02[1:d])  # flown by the first computer
    assert all(not b.alive and b.accel_cmd_mps2.y == 0.0 for b in sc02[d + 1:r])  # coasting
    assert all(b.alive for b in sc02[r:]) and any(b.accel_cmd_mps2.y != 0.0 for b in sc02[r + 1:])  # flown again
    acts = [a.header.step for a in _acts(tmp_path / "kill" / "run.mcap", "sc02")]
    assert max(a for a in acts if a < r) <= d and min(a for a in acts if a > d) >= r
    assert "fc: answered" in second_out, second_out


def test_slow_external_flight_computer_misses_real_time_deadlines_and_the_run_goes_on(tmp_path: Path,
                                                                                      fc_build: Path) -> None:
    """Real time at x50 (0.2 s a step) with a flight computer that takes 0.5 s a step: its misses are
    counted (deadline_missed events, summary missed_deadlines), its spacecraft is not dropped, the run
    completes on the wall clock."""
    flight = Flight(tmp_path / "rt", "hil4", fc_build, ["--mode", "realtime", "--speed", "50", "--duration", "300"],
                    fc_args=["--delay-s", "0.5"])
    code, out, err, fc_out = flight.finish()
    assert code == 0, (out, err, fc_out)
    s = json.loads((tmp_path / "rt" / "summary.json").read_text())
    assert s["steps"] == 30 and "sc02" not in s["dead_agents"], s
    assert s["missed_deadlines"].get("sc02", 0) >= 20, s["missed_deadlines"]
    msgs = read_mcap(tmp_path / "rt" / "run.mcap")
    missed = [m.header.step for t, _l, _p, m in msgs if t == "event" and m.kind == "deadline_missed" and m.subject == "sc02"]
    assert len(missed) == s["missed_deadlines"]["sc02"]
    doc = json.loads((flight.kit / "join.json").read_text())
    assert doc["timing"]["deadline"] == {**doc["timing"]["deadline"], "mode": "realtime", "wall_period_s": 0.2}


def _doc_blocks(name: str) -> tuple[list[list[str]], list[str]]:
    """(the shell commands of each block marked to be run by this test, every python block) of a doc."""
    import re

    text = (ROOT / "docs" / name).read_text()
    blocks = re.findall(r"<!-- run-by: tests/test_external_fsw.py::test_hil_doc_runs -->\n```sh\n(.*?)```", text, re.S)
    cmds = [[line.split("#")[0].strip() for line in b.splitlines() if line.split("#")[0].strip()] for b in blocks]
    return cmds, re.findall(r"```python\n(.*?)```", text, re.S)


def test_hil_doc_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """docs/hil.md's quick start as written (runs/hil in a temporary directory; the flight
    computer's build into one too), then its Python on the run."""
    (cmds, refly), python = _doc_blocks("hil.md")
    run_dir = tmp_path / "runs" / "hil"
    assert cmds == ["swarmhil run deploy/scenarios/hil-3.toml --out runs/hil --run-id hil",
                    "examples/external_fsw/build.sh",
                    "python examples/external_fsw/fc.py runs/hil/external/sc02"], cmds
    build = tmp_path / "build"
    args = [c.replace("runs/hil", str(run_dir)).split() for c in cmds]
    args[0][0:1] = SWARMHIL
    args[1] += [str(ROOT / "bus" / "swarmhil.proto"), str(build)]  # (into the test's directory)
    args[2][0:1] = [sys.executable]
    args[2] += ["--build", str(build)]
    launcher = subprocess.Popen([*args[0], "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=_env(), cwd=ROOT)
    try:
        r = subprocess.run(args[1], cwd=ROOT, env={**os.environ, "PYTHON": sys.executable}, capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        t_end = time.monotonic() + 120
        while not (run_dir / "external" / "sc02" / "join.json").exists() and time.monotonic() < t_end:
            time.sleep(0.1)
        fc = subprocess.run(args[2], cwd=ROOT, capture_output=True, text=True, timeout=300)
        out, err = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    assert fc.returncode == 0 and launcher.returncode == 0, (fc.stdout, fc.stderr, out, err)
    lines = out.splitlines()
    assert lines[0].startswith("waiting up to 300 s for the external flight software of sc02 to join at tcp/127.0.0.1:")
    assert lines[1].startswith("run hil: 300 steps") and "dead []" in lines[1], out
    ns: dict[str, object] = {}
    for code in python:
        exec(compile(code.replace('"runs/hil"', repr(str(run_dir))), "docs/hil.md", "exec"), ns)  # noqa: S102
    printed = capsys.readouterr().out
    assert "sc02 answered 300 of 300 steps" in printed and "dead []" in printed and "compute per step p50" in printed
    assert [c.split()[:4] for c in refly] == [["swarmhil", "refly", "runs/hil", "--agent"]] * 2, refly
    got = [subprocess.run([*SWARMHIL, *c.replace("runs/hil", str(run_dir)).split()[1:]], capture_output=True, text=True,
                          env=_env(), cwd=ROOT, timeout=120) for c in refly]
    assert got[0].returncode == 0 and got[0].stdout.startswith("sc02: identical over 300 steps"), got[0]
    assert got[1].returncode == 5 and got[1].stdout.startswith("sc01: first divergence at step 0 (t = 0 s): "
                                                               "accel_mps2.y recorded "), got[1]
    assert (run_dir / "refly-sc01" / "commands.csv").is_file()


@pytest.mark.system
def test_external_flight_computer_over_mutual_tls_from_its_own_namespace(tmp_path: Path, fc_build: Path) -> None:
    """The flight computer on another "host": the launcher and every process it starts in one network
    namespace (`r`), the flight computer in another (`a`), joined only by the veth links of the
    multi-host test (tests/test_multihost.py). `swarmhil run --tls --join-listen tls/10.213.1.1:7447`:
    the router also listens on r's address, the kit points there and carries the run's CA and the
    agent's client certificate (its certificate names that address). Same truth, bit for bit, as the
    built-in run on loopback without TLS."""
    from system_tools import require_command, require_root
    from test_multihost import ROUTER_IP, Hosts

    from swarmhil.deploy.launcher import MultiProcessRun

    require_root("network namespaces")
    require_command("ip", "iproute2")
    require_command("openssl", "openssl")
    out, ep = tmp_path / "tls", f"tls/{ROUTER_IP}:7447"
    hosts = Hosts()
    try:
        launcher = subprocess.Popen([*hosts.prefix("r"), *SWARMHIL, "run", str(SCENARIO), "--out", str(out), "--run-id",
                                     "hil3", "--no-progress", "--duration", "1000", "--tls", "--join-listen", ep,
                                     "--set", "spacecraft.1.join_timeout_s=90"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), cwd=ROOT)
        kit = out / "external" / "sc02"
        t_end = time.monotonic() + 120
        while not (kit / "join.json").exists():
            assert launcher.poll() is None and time.monotonic() < t_end, launcher.communicate()
            time.sleep(0.1)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        fc = subprocess.Popen([*hosts.prefix("a"), sys.executable, str(FC / "fc.py"), str(kit), "--build", str(fc_build)],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=tmp_path)
        # Where each really runs, sampled while the launcher is certainly alive (it waits for the join):
        # a fixed sleep once let a quick 100-step run end first, and r was then empty.
        while True:
            in_a, in_r = hosts.pids("a"), hosts.pids("r")
            assert launcher.poll() is None or (fc.pid in in_a and launcher.pid in in_r), "the run ended before it was seen"
            if fc.pid in in_a and launcher.pid in in_r:
                break
            assert time.monotonic() < t_end, (in_a, in_r)
            time.sleep(0.05)
        code = launcher.wait(300)
        fc_out, _ = fc.communicate(timeout=60)
        l_out, l_err = launcher.communicate()
    finally:
        hosts.close()
    assert code == 0 and fc.returncode == 0, (l_out, l_err, fc_out)
    assert fc.pid in in_a and launcher.pid in in_r and in_a.isdisjoint(in_r), (in_a, in_r)
    assert "fc: answered 100 stimuli" in fc_out, fc_out
    doc = json.loads((kit / "join.json").read_text())
    assert doc["router"] == [ep] and doc["zenoh"]["connect/endpoints"] == [ep]
    assert doc["tls"] == {"ca": "tls/ca.pem", "cert": "tls/agent-sc02.pem", "key": "tls/agent-sc02.key"}
    assert l_out.splitlines()[0].startswith(f"waiting up to 90 s for the external flight software of sc02 to join at {ep} ")
    s = json.loads((out / "summary.json").read_text())
    assert s["tls"] and s["secure"] and s["steps"] == 100 and not s["dead_agents"] and s["rejected_packets"] == 0, s

    sc = load_scenario(SCENARIO, ["spacecraft.1.fsw=builtin"]).with_overrides(duration_s=1000.0)
    ref = MultiProcessRun(str(SCENARIO), sc, tmp_path / "builtin", "hil3", progress=False,
                          overrides={"duration": 1000.0}).execute()
    assert ref.exit_code == 0, ref.reason
    truth = _truth(out / "run.mcap")
    assert len(truth) == 101 and truth == _truth(tmp_path / "builtin" / "run.mcap")
    assert s["delta_v_mps"]["sc02"] > 0 and s["delta_v_mps"] == ref.summary["delta_v_mps"]


def test_kit_tls_paths_work_from_any_directory_and_a_missing_file_fails_fast(tmp_path: Path, fc_build: Path) -> None:
    """A --tls kit: the `zenoh` block names its TLS files by absolute paths that exist (it works as
    given from any working directory), `tls` by names relative to the kit (a copied kit finds them);
    the reference flight computer with a kit whose CA file is gone stops at once with one line
    naming the file, not after the 15 s connect timeout."""
    from swarmhil.bus.acl import make_run_security
    from swarmhil.deploy.external import write_join_kit

    sc = load_scenario(SCENARIO)
    (tmp_path / "secrets").mkdir()
    sec = make_run_security(tmp_path / "secrets", "kt", ["plant", "agent-sc02"], tls=True)
    kit = write_join_kit(tmp_path / "run", sc, "kt", "sc02", ["tls/127.0.0.1:1"], sec)
    doc = json.loads((kit / "join.json").read_text())
    tls = {k: v for k, v in doc["zenoh"].items() if k.startswith("transport/link/tls/") and isinstance(v, str)}
    assert len(tls) == 3 and all(Path(v).is_absolute() and Path(v).is_file() for v in tls.values()), tls
    assert sorted(tls.values()) == sorted(str(kit.resolve() / v) for v in doc["tls"].values())
    moved = tmp_path / "elsewhere" / "kit"
    import shutil

    shutil.copytree(kit, moved)
    shutil.rmtree(kit)  # the absolute paths now point nowhere; the copy resolves `tls` itself
    (moved / "tls" / "ca.pem").unlink()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, str(FC / "fc.py"), str(moved), "--build", str(fc_build)], capture_output=True,
                       text=True, env=env, cwd=tmp_path, timeout=60)
    assert time.monotonic() - t0 < 10.0 and r.returncode == 1, (r.stdout, r.stderr)
    assert r.stderr.strip() == (f"fc: {moved}/join.json: TLS file {moved.resolve()}/tls/ca.pem "
                                f"(transport/link/tls/root_ca_certificate) does not exist"), r.stderr


def test_the_doc_drift_null_law_is_the_built_in_bit_for_bit() -> None:
    """docs/hil.md "The built-in laws, to the bit": the drift-null steps written in plain Python
    floats (no numpy) give the built-in controller's command bit for bit, for 0 to 7 neighbours
    over many random states, including ones the clip cuts."""
    import random

    import numpy as np

    from swarmhil.agent.controller import Observation, OrbitInfo
    from swarmhil.agent.controllers import DriftNullController

    def doc_law(pos: list, vel: list, n: float, gain: float, amax: float) -> tuple[float, float, float]:
        if not pos:
            return (0.0, 0.0, 0.0)
        da = [(4.0 * p[0]) + ((2.0 * v[1]) / n) for p, v in zip(pos, vel)]
        total = 0.0
        for d in da:
            total += d
        m = total / len(da)
        u = ((gain * n) / 2.0) * m
        return (0.0, min(max(u, -amax), amax), 0.0)

    rnd = random.Random(37)
    n = 0.0011082
    checked = clipped = 0
    for _ in range(3000):
        k = rnd.randrange(0, 8)
        pos = [[rnd.uniform(-1, 1) * 10 ** rnd.uniform(-2, 3) for _ in range(3)] for _ in range(k)]
        vel = [[rnd.uniform(-1, 1) * 10 ** rnd.uniform(-4, 0) for _ in range(3)] for _ in range(k)]
        gain, amax = 10 ** rnd.uniform(-5, -2), 10 ** rnd.uniform(-5, -2)
        obs = Observation(step=0, t_s=0.0, u_rad=0.0, neighbour_ids=[f"n{i}" for i in range(k)],
                          rel_position_m=np.array(pos, dtype=float).reshape(-1, 3),
                          rel_velocity_mps=np.array(vel, dtype=float).reshape(-1, 3))
        built_in = DriftNullController(OrbitInfo(7e6, n), gain, amax).step(obs)
        want = doc_law(pos, vel, n, gain, amax)
        assert tuple(built_in.accel_mps2.tolist()) == want, (k, built_in.accel_mps2, want)
        assert built_in.mode == ("search" if k == 0 else "drift-null")
        checked += 1
        clipped += abs(want[1]) == amax
    assert checked == 3000 and 100 < clipped < 2900   # both branches of the clip were exercised
