"""One run over four hosts through a mesh of Zenoh routers (`swarmhil run --hosts 4`, deploy/mesh.py),
on loopback: the same truth, bit for bit, and the same messages on every topic of run.mcap as the
single-router run with the same run id and seed; lockstep with no dead agent and no missed step; every
agent a client of its own host's router only, every router linked to the routers before it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import psutil
import pytest

from conftest import ROOT, SCENARIOS, read_mcap, topics

pytestmark = pytest.mark.system

RUN = "mesh4"
DURATION_S = "400"  # 40 steps of sabatini-20


def _launch(out: Path, hosts: int, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "sabatini-20.toml"),
                             "--duration", DURATION_S, "--run-id", RUN, "--out", str(out), "--no-progress",
                             "--hosts", str(hosts), *extra], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


@pytest.fixture(scope="module")
def single_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The single-router run the mesh runs are compared with (same scenario, run id and seed)."""
    out = tmp_path_factory.mktemp("single") / "hosts1"
    p = _launch(out, 1)
    _out, err = p.communicate(timeout=600)
    assert p.returncode == 0, err[-2000:]
    one = json.loads((out / "run.json").read_text())
    assert len(one["hosts"]) == 1 and set(one["process_hosts"].values()) == {0}
    return out


def _assert_same_recording(mesh_out: Path, single_out: Path) -> None:
    """The same truth bit for bit and the same messages on every topic (see `_by_topic`)."""
    truth = topics(mesh_out / "run.mcap", "truth")
    assert len(truth) == 41 and truth == topics(single_out / "run.mcap", "truth")
    mesh, single = _by_topic(mesh_out / "run.mcap"), _by_topic(single_out / "run.mcap")
    assert sorted(mesh) == sorted(single)
    assert {t: len(v) for t, v in mesh.items()} == {t: len(v) for t, v in single.items()}
    # every topic the processes publish holds the same messages; the recorder's own Foxglove scene
    # colours each spacecraft by the last telemetry it had when a truth arrived, so it depends on
    # the arrival order of the two at the recorder (timing, not content): compared in number only
    differ = [t for t in single if t != "foxglove/scene" and sorted(mesh[t]) != sorted(single[t])]
    assert not differ, differ
    s = json.loads((mesh_out / "summary.json").read_text())
    assert s["steps"] == 40 and s["dead_agents"] == {} and s["missed_deadlines"] == {} and s["late_commands"] == 0, s
    assert s["rejected_packets"] == 0 and s["recorder_confirmed"]
    assert s["delta_v_mps"] == json.loads((single_out / "summary.json").read_text())["delta_v_mps"]


def _port(ep: str) -> int:
    return int(ep.rpartition(":")[2])


def _remote_ports(pid: int) -> set[int]:
    try:
        return {c.raddr.port for c in psutil.Process(pid).net_connections(kind="tcp")
                if c.raddr and c.status == psutil.CONN_ESTABLISHED}
    except psutil.NoSuchProcess:
        return set()


def _run_json(p: subprocess.Popen, out: Path, timeout_s: float = 300.0) -> dict:
    """run.json once the launcher has started every process (the plant last)."""
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end and p.poll() is None:
        try:
            info = json.loads((out / "run.json").read_text())
            if "plant" in info["pids"]:
                return info
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.05)
    raise AssertionError(f"the run ended (code {p.poll()}) or took {timeout_s:.0f} s before run.json named its processes")


def _connections_while_running(p: subprocess.Popen, out: Path) -> tuple[dict, dict[str, set[int]]]:
    """run.json once every process is started, and the TCP peers (remote ports) of every agent and
    router, sampled while the run goes on (until every agent has one)."""
    t_end = time.monotonic() + 300
    info = _run_json(p, out)
    seen: dict[str, set[int]] = defaultdict(set)
    names = [n for n in info["pids"] if n.startswith(("agent-", "router"))]
    while time.monotonic() < t_end and p.poll() is None:
        for n in names:
            seen[n] |= _remote_ports(info["pids"][n])
        if all(seen[n] for n in names if n.startswith("agent-")) and all(seen[n] for n in names if n.startswith("router-")):
            break
        time.sleep(0.1)
    return info, seen


def _by_topic(path: Path) -> dict[str, list[bytes]]:
    """Every message of the recording, serialized, by topic (in recorded order); the telemetry's
    `compute_s` (wall time the flight software spent) zeroed, the one field a run's timing sets."""
    d: dict[str, list[bytes]] = defaultdict(list)
    for topic, _log, _pub, msg in read_mcap(path):
        if topic.endswith("/tm"):
            msg.compute_s = 0.0
        d[topic].append(msg.SerializeToString())
    return d


def test_four_hosts_equal_one_router(tmp_path: Path, single_run: Path) -> None:
    mesh_out = tmp_path / "hosts4"
    p = _launch(mesh_out, 4)
    try:
        info, seen = _connections_while_running(p, mesh_out)
        stdout, stderr = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 0, stderr[-2000:]

    # placement: round-robin, the ground processes on host 0, one router per host, in run.json
    hosts = info["hosts"]
    assert [h["host"] for h in hosts] == [0, 1, 2, 3]
    assert [h["router_process"] for h in hosts] == ["router", "router-1", "router-2", "router-3"]
    assert len({h["router"] for h in hosts}) == 4 and len({h["zid"] for h in hosts}) == 4
    ph = info["process_hosts"]
    assert all(ph[f"agent-sc{i + 1:02d}"] == i % 4 for i in range(20)), ph
    assert ph["plant"] == ph["recorder"] == 0 and ph["router-3"] == 3
    port_of_host = [_port(h["router"]) for h in hosts]
    # each agent talks to its own host's router and to nothing else
    for i in range(20):
        name = f"agent-sc{i + 1:02d}"
        assert seen[name] == {port_of_host[i % 4]}, (name, seen[name], port_of_host)
    # router i links to every router before it (a full mesh: router 3 to routers 0, 1, 2)
    for h in range(1, 4):
        assert set(port_of_host[:h]) <= seen[f"router-{h}"], (h, seen[f"router-{h}"], port_of_host)

    assert json.loads((mesh_out / "summary.json").read_text())["hosts"] == hosts
    _assert_same_recording(mesh_out, single_run)


def test_four_namespaced_hosts_on_tls_equal_one_router(tmp_path: Path, single_run: Path) -> None:
    """`--hosts 4 --netns --tls`: hosts 1..3 network namespaces with their own addresses, mutual TLS
    on every link (router to router included), the run's ACL on every router: every process runs in
    its host's namespace, and the recording is the single-router run's."""
    from system_tools import require_command, require_root

    require_root("network namespaces")
    require_command("ip", "iproute2")
    require_command("openssl", "openssl")
    out = tmp_path / "ns4"
    p = _launch(out, 4, "--netns", "--tls")
    placed: dict[int, set[int]] = {}
    try:
        info = _run_json(p, out)
        want = {h: {info["pids"][n] for n, hh in info["process_hosts"].items() if hh == h} for h in range(1, 4)}
        t_end = time.monotonic() + 60  # (a process enters its namespace just after it is started)
        while time.monotonic() < t_end and p.poll() is None:
            for h in range(1, 4):
                r = subprocess.run(["ip", "netns", "pids", info["hosts"][h]["netns"]], capture_output=True, text=True)
                assert r.returncode == 0, r.stderr
                placed[h] = {int(x) for x in r.stdout.split()}
            if all(want[h] <= placed[h] for h in want):
                break
            time.sleep(0.1)
        _stdout, err = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 0, err[-2000:]
    hosts = info["hosts"]
    addresses = [h["address"] for h in hosts]
    assert len(set(addresses)) == 4 and hosts[0]["netns"] is None
    assert all(h["router"] == f"tls/{h['address']}:{_port(h['router'])}" for h in hosts), hosts
    for name, host in info["process_hosts"].items():
        pid = info["pids"][name]
        if host:
            assert pid in placed[host], (name, host, placed)
        assert all(pid not in placed[h] for h in placed if h != host), (name, host)
    assert all(info["process_hosts"][f"agent-sc{i + 1:02d}"] == i % 4 for i in range(20))
    left = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert not any(h["netns"] and h["netns"] in left for h in hosts), left  # the run removed them
    _assert_same_recording(out, single_run)


def _kill_router_2(out: Path, *sets: str) -> tuple[dict, list, dict[str, int]]:
    """sabatini-20 with 6 agents over 3 hosts (real time x20, 40 steps), host 2's router SIGKILLed at
    step 8: (summary.json, the recorded events, commands recorded per spacecraft)."""
    import signal

    from swarmhil.bus import swarmhil_pb2 as pb
    from swarmhil.bus.acl import read_credential
    from swarmhil.bus.zenoh_bus import ZenohBus

    p = subprocess.Popen([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "sabatini-20.toml"),
                          "--set", "dispersion.count=6", *[x for kv in sets for x in ("--set", kv)], "--duration", "400",
                          "--mode", "realtime", "--speed", "20", "--run-id", "kr", "--out", str(out), "--no-progress",
                          "--hosts", "3"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info = _run_json(p, out)
        assert info["process_hosts"]["agent-sc03"] == info["process_hosts"]["agent-sc06"] == 2
        step = threading.Event()
        bus = ZenohBus(info["router"], credential=read_credential(out / "secrets" / "launcher.cred"))
        bus.subscribe("swarm/kr/clock", lambda _k, b: pb.Tick.FromString(b).header.step >= 8 and step.set())
        try:
            assert step.wait(120), "the run did not reach step 8"
        finally:
            bus.close()
        os.kill(info["pids"]["router-2"], signal.SIGKILL)
        _out, err = p.communicate(timeout=600)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 0, err[-2000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["steps"] == 40
    events, acts = [], defaultdict(int)
    for t, _l, _p, m in read_mcap(out / "run.mcap"):
        if t == "event":
            events.append(m)
        elif t.endswith("/act"):
            acts[t.split("/")[1]] += 1
    # the agents of the other hosts commanded every step to the end
    assert all(acts[f"sc0{i}"] == 40 for i in (1, 2, 4, 5)), acts
    return s, events, acts


def test_a_killed_router_of_another_host_marks_its_agents_dead(tmp_path: Path) -> None:
    """SIGKILL of host 2's router mid-run (3 hosts, 6 agents): its agents (sc03, sc06) are marked dead
    and their spacecraft coast, the other agents fly on to the end, the run completes (exit 0) and
    the launcher's Event `router_lost` is in the recording."""
    s, events, acts = _kill_router_2(tmp_path / "kr")
    assert sorted(s["dead_agents"]) == ["sc03", "sc06"], s["dead_agents"]
    assert s["exit_codes"]["router-2"] == -9
    lost = [e for e in events if e.kind == "router_lost"]
    assert len(lost) == 1 and lost[0].subject == "router-2" and "sc03, sc06" in lost[0].detail, lost
    assert {e.subject for e in events if e.kind == "agent_dead"} == {"sc03", "sc06"}
    assert all(8 <= acts[f"sc0{i}"] < 40 for i in (3, 6)), acts  # the lost ones stopped early


def test_a_killed_router_of_another_host_restarts_and_its_agents_rejoin(tmp_path: Path) -> None:
    """The same with `restart = "on-failure"`: the launcher starts host 2's router again on its
    endpoint (Event `router_restart`), its agents' sessions reconnect and the plant takes them back
    (`agent_rejoin`); nobody is dead at the end."""
    s, events, acts = _kill_router_2(tmp_path / "kr", 'supervision.restart="on-failure"')
    assert s["restarts"].get("router-2") == 1 and len(s["all_pids"]["router-2"]) == 2, s["restarts"]
    assert [e.subject for e in events if e.kind == "router_restart"] == ["router-2"]
    assert not [e for e in events if e.kind == "router_lost"]
    assert {e.subject for e in events if e.kind == "agent_dead"} == {"sc03", "sc06"}
    assert {r["id"] for r in s["rejoins"]} == {"sc03", "sc06"}, s["rejoins"]
    assert s["dead_agents"] == {}, s["dead_agents"]
    back = {r["id"]: r["step"] for r in s["rejoins"]}
    # commanded before the kill (steps 0 .. 7 at least) and again from the step they rejoined at
    assert all(7 + (40 - back[sid]) <= acts[sid] < 40 for sid in ("sc03", "sc06")), (acts, back)


def test_a_crashed_agent_of_another_host_restarts_and_rejoins(tmp_path: Path) -> None:
    """`restart = "on-failure"` over 3 hosts: sc03 (host 2) crashed by a process fault is started again
    on its own host's router and rejoins; nobody is dead at the end."""
    from swarmhil.deploy.launcher import MultiProcessRun
    from swarmhil.deploy.scenario import load_scenario

    scen = tmp_path / "crash.toml"
    scen.write_text((SCENARIOS / "sabatini-20.toml").read_text()
                    + '\n[[fault]]\nkind = "process_crash"\ntargets = ["sc03"]\nstart_s = 50.0\n')
    sc = load_scenario(scen, ("dispersion.count=6", 'supervision.restart="on-failure"', "run.duration_s=3000"))
    res = MultiProcessRun(str(scen), sc, tmp_path / "out", "crash3", progress=False, opts={"hosts": 3}).execute()
    assert res.exit_code == 0, res.reason
    s = res.summary
    assert s["process_hosts"]["agent-sc03"] == 2
    assert s["restarts"] == {"agent-sc03": 1} and [r["id"] for r in s["rejoins"]] == ["sc03"], (s["restarts"], s["rejoins"])
    assert s["dead_agents"] == {} and len(s["all_pids"]["agent-sc03"]) == 2
