"""Authentication and access control of a multi-process run (issue 17), over real Zenoh on loopback.

The router of every multi-process run reads a per-run user/password dictionary and an access
control list (bus/acl.py): a process without credentials cannot open a session; an authenticated
one may publish only on its own keys. The receivers still validate every message (header, run,
source, step): a sample without a header and a command cut short are rejected.
"""
from __future__ import annotations

import json
import math
import stat
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.acl import acl_config, make_run_security
from swarmhil.bus.codec import RejectedPacket, decode, header, vec
from swarmhil.bus.keys import Keys
from swarmhil.bus.zenoh_bus import ZenohBus, endpoint, free_loopback_port, open_router
from conftest import assert_refused, read_mcap

RUN = "secrun"


# --- the ACL itself, on a router in this process -------------------------------------------------
@pytest.fixture
def secured(tmp_path: Path):
    sec = make_run_security(tmp_path, RUN, ["plant", "channel", "recorder", "agent-a", "agent-b"])
    ep = endpoint(free_loopback_port())
    router = open_router(ep, sec.router_overrides())
    buses: list[ZenohBus] = []

    def bus(user: str) -> ZenohBus:
        b = ZenohBus(ep, credential=sec.credential(user))
        buses.append(b)
        return b

    yield sec, ep, bus
    for b in buses:
        b.close()
    router.close()


def test_credential_files_are_private(tmp_path: Path) -> None:
    sec = make_run_security(tmp_path, RUN, ["plant", "agent-a"])
    assert stat.S_IMODE(sec.dir.stat().st_mode) == 0o700
    for p in [sec.dictionary, *sec.credentials.values()]:
        assert stat.S_IMODE(p.stat().st_mode) == 0o600, p
    assert sec.credential("plant").password != sec.credential("agent-a").password
    acl = acl_config(RUN, ["agent-a"])
    assert acl["default_permission"] == "deny"
    put = next(r for r in acl["rules"] if r["id"] == "agent-a:put")
    assert put["key_exprs"] == [f"swarm/{RUN}/sc/a/act", f"swarm/{RUN}/sc/a/tm", f"swarm/{RUN}/sc/a/tm/**",
                                f"swarm/{RUN}/isl/tx/a"]


def test_no_or_wrong_credentials_cannot_connect(secured, monkeypatch: pytest.MonkeyPatch) -> None:
    from swarmhil.bus import acl

    sec, ep, _bus = secured
    # no credential, a wrong password, and a password of another process (agent-b's) for agent-a;
    # agent-a's own connects to the same router before and after (conftest.assert_refused)
    bad = [None, acl.Credential("agent-a", "not-the-password"),
           acl.Credential("agent-a", sec.credential("agent-b").password)]
    assert_refused(ep, sec.credential("agent-a"), [(ep, c) for c in bad], monkeypatch)


def _wait_for(cond, what: str, timeout_s: float = 30.0) -> None:
    t_end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < t_end, f"not within {timeout_s} s: {what}"
        time.sleep(0.01)


def test_an_agent_publishes_only_its_own_keys(secured) -> None:
    _sec, _ep, bus = secured
    k = Keys(RUN)
    plant, channel, rec, a, b = bus("plant"), bus("channel"), bus("recorder"), bus("agent-a"), bus("agent-b")
    got: dict[str, list] = {"plant": [], "channel": [], "rec": [], "b": [], "alive": []}
    plant.subscribe(k.act_all, lambda key, p: got["plant"].append((key, bytes(p))))
    plant.watch_liveliness(k.alive_all, lambda key, up: got["alive"].append(key) if up else None)
    channel.subscribe(k.clock, lambda key, _p: got["channel"].append(key))
    rec.subscribe(k.all, lambda key, p: got["rec"].append((key, bytes(p))))
    b.subscribe(k.sense("b", "rel"), lambda key, p: got["b"].append((key, bytes(p))))
    a.subscribe(k.sense("b", "rel"), lambda key, p: got["b"].append(("spy:" + key, bytes(p))))  # not a's to read
    a.declare_liveliness(k.alive("agent-a"))
    a.declare_liveliness(k.alive("plant"))  # a forged liveliness token
    # synchronised on what arrives, not on sleeps: first every subscription is in place (a probe on
    # each allowed path gets through, the liveliness of agent-a is seen) ...
    _wait_for(lambda: k.alive("agent-a") in got["alive"], "agent-a's liveliness at the plant")

    def probe(tag: bytes) -> None:
        _wait_for(lambda: (a.publish(k.act("a"), tag), plant.publish(k.sense("b", "rel"), tag))
                  and (k.act("a"), tag) in got["plant"] and (k.sense("b", "rel"), tag) in got["b"]
                  and {(k.act("a"), tag), (k.sense("b", "rel"), tag)} <= set(got["rec"]), f"probe {tag!r}")

    probe(b"probe")
    for name in ("plant", "channel", "rec", "b"):
        got[name].clear()
    for _ in range(3):
        a.publish(k.act("a"), b"own")
        a.publish(k.act("b"), b"forged")       # another agent's command key
        a.publish(k.clock, b"forged")          # the plant's clock
        a.publish(k.truth, b"forged")
        a.publish(k.isl_rx("b"), b"forged")    # the channel's delivery key
        a.publish(k.sync("channel"), b"forged")
        plant.publish(k.sense("b", "rel"), b"stim")
    # ... then an end marker after the forgeries, from the same sessions: once it has arrived, every
    # earlier sample from a and from the plant has been routed (one session's samples stay in order)
    probe(b"end")
    # (probes repeated before the first one arrived may still come in: not counted)
    def counted(xs: list) -> list:
        return [x for x in xs if x[1] not in (b"probe", b"end")]

    sent = [(k.act("a"), b"own")] * 3
    assert counted(got["plant"]) == sent
    assert got["channel"] == []
    stim = [(k.sense("b", "rel"), b"stim")] * 3
    assert sorted(counted(got["rec"])) == sorted(sent + stim), got["rec"]
    assert counted(got["b"]) == stim
    assert got["alive"] == [k.alive("agent-a")]  # the forged plant token was declared before the probes


# --- validation in every receiver -----------------------------------------------------------------
def test_a_message_without_header_is_rejected() -> None:
    for cls in (pb.ActuatorCommand, pb.Tick, pb.Truth, pb.IslPacket, pb.RelStimulus, pb.Measurements):
        with pytest.raises(RejectedPacket, match="no header"):
            decode(cls, b"", run=RUN)


def test_a_non_finite_value_in_a_long_array_is_rejected() -> None:
    """The walk sums each repeated double field first (issue 29): a NaN/inf anywhere in a long
    array (a landmark cloud) is still found and named; finite values whose sum overflows pass."""
    from swarmhil.bus.codec import add_measurement

    rng = np.random.default_rng(29)
    for bad in (math.nan, math.inf, -math.inf):
        for at in (0, 577, 1199):
            msg = pb.Measurements(header=header(RUN, "plant", 1, 0.05, 1))
            vals = rng.uniform(-8.5, 8.5, 1200)
            vals[at] = bad
            add_measurement(msg, "p000_landmarks_body_m", vals.reshape(-1, 3))
            with pytest.raises(RejectedPacket, match=f"non-finite value items\\[0\\].values={bad}"):
                decode(pb.Measurements, msg.SerializeToString(), run=RUN)
    msg = pb.Measurements(header=header(RUN, "plant", 1, 0.05, 1))
    add_measurement(msg, "big", [1.7e308, 1.7e308, -1e308])  # sum overflows to inf: walked, all finite
    assert list(decode(pb.Measurements, msg.SerializeToString(), run=RUN).items[0].values) == [1.7e308, 1.7e308, -1e308]


def test_a_truncated_command_is_rejected() -> None:
    from swarmhil.plant.node import PlantNode  # noqa: F401  (the plant runs check_complete_command on every command)
    from swarmhil.bus.codec import check_complete_command

    full = pb.ActuatorCommand(header=header(RUN, "a", 3, 30.0, 3), accel_mps2=vec([1e-3, 0, 0]), controller="null")
    data = full.SerializeToString()
    check_complete_command(decode(pb.ActuatorCommand, data, run=RUN))
    n_header = len(pb.ActuatorCommand(header=full.header).SerializeToString())
    n_accel = len(pb.ActuatorCommand(header=full.header, accel_mps2=full.accel_mps2).SerializeToString())
    for cut in (n_header, n_accel):  # cut at a field boundary: parses, but incomplete
        with pytest.raises(RejectedPacket, match="truncated"):
            check_complete_command(decode(pb.ActuatorCommand, data[:cut], run=RUN))
    for cut in range(1, len(data)):  # anywhere else: does not parse, or is incomplete
        with pytest.raises(RejectedPacket):
            check_complete_command(decode(pb.ActuatorCommand, data[:cut], run=RUN))


# --- a whole run, attacked --------------------------------------------------------------------------
SCENARIO = """
[run]
name = "sec"
duration_s = 200.0
step_s = 10.0
seed = 5

[controller]
name = "null"

[dispersion]
count = 4
sigma_roe_m = [30.0, 40.0, 30.0, 30.0, 30.0, 30.0]
along_track_spacing_m = 200.0

[link]
range_m = 400.0
loss_probability = 0.0
overhead_bytes = 24
stats_period_s = 50.0

[beacon]
period_s = 10.0
"""


# sc04's commands leave 0.5 s late (bus/faults.py), in both runs: every lockstep step stays open
# that long after sc02's and sc03's real commands arrived, so a forgery sent then would replace
# them (the plant keeps the last command of a step). Lockstep results do not depend on the delay.
FAULTS = {"agent-sc04": {"delay_tx": {"/act": 0.5}}}


def _attack(out: Path, stop: threading.Event, report: dict, with_credentials: bool = True,
            final_tick: bool = True) -> None:
    """A neighbour holding agent sc01's credentials: keeps forging sc02's and sc03's commands (their
    key, their id in header.source, every step) and the plant's final tick; and one with no
    credentials at all."""
    from swarmhil.bus import zenoh_bus
    from swarmhil.bus.acl import read_credential

    while not (out / "run.json").exists() and not stop.is_set():
        time.sleep(0.02)
    ep = json.loads((out / "run.json").read_text())["router"]
    if with_credentials:
        old = zenoh_bus.CONNECT_TIMEOUT_MS
        try:
            zenoh_bus.CONNECT_TIMEOUT_MS = 1500
            try:
                ZenohBus(ep).close()
                report["anonymous"] = "connected"
            except zenoh.ZError:
                report["anonymous"] = "refused"
        finally:
            zenoh_bus.CONNECT_TIMEOUT_MS = old
    cred = read_credential(out / "secrets" / "agent-sc01.cred") if with_credentials else None
    bus = ZenohBus(ep, credential=cred)
    k = Keys(RUN)
    sent = 0
    try:
        while not stop.is_set():
            for sid in ("sc02", "sc03"):
                for step in range(0, 21):
                    cmd = pb.ActuatorCommand(header=header(RUN, sid, step, step * 10.0, 0),
                                             accel_mps2=vec([5e-3, -5e-3, 5e-3]), controller="null")
                    bus.publish(k.act(sid), cmd.SerializeToString())
                    sent += 1
            if final_tick and sent > 2000:  # the run is well under way: the plant's final tick, forged
                final = pb.Tick(header=header(RUN, "plant", 3, 30.0, 0), final=True)
                bus.publish(k.clock, final.SerializeToString())
            time.sleep(0.1)
    finally:
        report["forged"] = sent
        bus.close()


def _secure_run(d: Path, attack: bool, secure: bool = True, final_tick: bool = True) -> tuple[Path, dict]:
    from swarmhil.deploy.launcher import MultiProcessRun
    from swarmhil.deploy.scenario import load_scenario

    d.mkdir(parents=True, exist_ok=True)
    path = d / "sec.toml"
    path.write_text(SCENARIO)
    out = d / "out"
    report: dict = {}
    stop = threading.Event()
    t = threading.Thread(target=_attack, args=(out, stop, report, secure, final_tick), daemon=True) if attack else None
    if t:
        t.start()
    mp = pytest.MonkeyPatch()
    mp.setenv("SWARMHIL_FAULTS", json.dumps(FAULTS))
    try:
        run = MultiProcessRun(str(path), load_scenario(path), out, RUN, progress=False)
        run.secure = secure
        res = run.execute()
    finally:
        mp.undo()
        stop.set()
        if t:
            t.join(10)
    assert res.summary["secure"] is secure
    if secure:
        assert res.exit_code == 0, res.reason
    return out, {**report, **res.summary}


@pytest.fixture(scope="module")
def clean_and_attacked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, Path, dict]:
    d = tmp_path_factory.mktemp("sec")
    clean, s_clean = _secure_run(d / "clean", attack=False)
    attacked, s_att = _secure_run(d / "attacked", attack=True)
    return clean, s_clean, attacked, s_att


def _topics(out: Path, part: str) -> list[tuple[str, bytes]]:
    """Every message on the matching topics (the key without `swarm/<run>/`, matched from its start
    or after a '/'), in a canonical order (arrival order across processes varies)."""
    return sorted((t, m.SerializeToString()) for t, _l, _p, m in read_mcap(out / "run.mcap")
                  if t.startswith(part) or f"/{part}" in t)


def test_forged_commands_and_final_tick_move_nothing(clean_and_attacked) -> None:
    clean, s_clean, attacked, s_att = clean_and_attacked
    assert s_att["anonymous"] == "refused"
    assert s_att["forged"] >= 243
    # truth, commands and deliveries identical to the undisturbed run with the same run id
    for key in ("truth", "act", "isl/rx/"):
        assert _topics(clean, key), key
        assert _topics(attacked, key) == _topics(clean, key), key
    assert s_att["delta_v_mps"] == s_clean["delta_v_mps"]
    # the forgeries never reached the plant (stopped by the router, not by the plant's checks)
    assert s_att["rejected_packets"] == 0
    # the channel was not stopped by the forged final tick: every window closed on its own
    ch = s_att["channel"]
    assert ch["windows"] == s_att["steps"] == 20 and ch["forced_windows"] == 0, ch
    assert not s_att["dead_agents"] and not s_att["missed_deadlines"]


def test_the_same_forgery_moves_the_truth_of_an_insecure_run(clean_and_attacked, tmp_path: Path) -> None:
    """The positive control of the test above: the same attacker and the same forged commands on a
    run with --insecure (an open router, no credentials needed) must move sc02's and sc03's truth,
    or the identical truth of the secure run proves nothing. (Without the forged final tick: with it,
    the insecure run did not end within the 600 s test timeout on a loaded 2-core machine.)"""
    clean, s_clean, _attacked, _s_att = clean_and_attacked
    insecure, s_ins = _secure_run(tmp_path / "insecure", attack=True, secure=False, final_tick=False)
    assert s_ins["forged"] >= 243
    dv_clean, dv_ins = s_clean["delta_v_mps"], s_ins["delta_v_mps"]
    print("delta-v clean", dv_clean, "insecure, attacked", dv_ins)
    # null controller: no delta-v at all undisturbed; the forged 5e-3 m/s^2 per axis (clipped to
    # 1e-3) reaches the plant for the forged craft only (measured: every one of the 20 steps,
    # sqrt(3) 1e-3 m/s^2 x 200 s = 0.346 m/s each)
    assert all(v == 0.0 for v in dv_clean.values()), dv_clean
    assert dv_ins["sc02"] > 0.0 and dv_ins["sc03"] > 0.0, dv_ins
    assert dv_ins["sc01"] == 0.0 and dv_ins["sc04"] == 0.0, dv_ins
    assert _topics(insecure, "truth") != _topics(clean, "truth")
