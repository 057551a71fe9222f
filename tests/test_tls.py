"""Mutual TLS with the run's certificates (bus/tls.py), over real Zenoh on loopback.

A router on a `tls/` endpoint with the run's dictionary, ACL and certificates accepts a process
that presents its certificate (signed by the run's CA) and its password, and refuses one that
presents no certificate, a certificate of another run's CA, or plain TCP.
"""
from __future__ import annotations

import stat
import time
from pathlib import Path

import pytest

from swarmhil.bus.acl import make_run_security
from swarmhil.bus.keys import Keys
from swarmhil.bus.zenoh_bus import ZenohBus, endpoint, free_loopback_port, open_router
from conftest import assert_refused
from system_tools import require_command

RUN = "tlsrun"


@pytest.fixture(autouse=True)
def _openssl() -> None:
    require_command("openssl", "openssl")  # a failure in CI, a skip with the install command elsewhere


def test_tls_files_are_private_and_the_ca_key_is_gone(tmp_path: Path) -> None:
    sec = make_run_security(tmp_path, RUN, ["plant", "agent-a"], tls=True)
    d = sec.tls.dir
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    assert sorted(p.name for p in d.iterdir()) == sorted(
        ["ca.pem", "router.pem", "router.key", "plant.pem", "plant.key", "agent-a.pem", "agent-a.key"])
    for p in d.iterdir():
        assert stat.S_IMODE(p.stat().st_mode) == 0o600, p


def test_only_a_certificate_of_the_run_opens_a_session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from swarmhil.bus.acl import Credential

    for d in ("run", "other"):
        (tmp_path / d).mkdir()
    sec = make_run_security(tmp_path / "run", RUN, ["plant", "agent-a"], tls=True)
    other = make_run_security(tmp_path / "other", RUN, ["agent-a"], tls=True)  # another run's CA
    port = free_loopback_port()
    ep = endpoint(port, proto="tls")
    router = open_router(ep, sec.router_overrides())
    buses: list[ZenohBus] = []
    try:
        good = sec.credential("agent-a")
        plain = Credential(good.user, good.password)  # the right password, no certificate
        # refused: trusting the run's CA but showing no certificate of its own; a certificate of
        # another run's CA; plain TCP to the TLS port. Each waits 5x what agent-a's own certificate
        # takes to connect to the same router, before and after (a TLS handshake on a loaded 2-core
        # machine can take over 1.5 s: a fixed 1.5 s refused everything there)
        assert_refused(ep, good, [
            (ep, Credential(good.user, good.password,
                            {"transport/link/tls/root_ca_certificate": str(sec.tls.dir / "ca.pem")})),
            (ep, Credential(good.user, good.password).with_tls(other.tls.dir)),
            (endpoint(port), plain)], monkeypatch)
        # the run's own certificate and password: a working session, under the ACL
        plant = ZenohBus(ep, credential=sec.credential("plant"))
        buses.append(plant)
        agent = ZenohBus(ep, credential=good)
        buses.append(agent)
        k = Keys(RUN)
        got: list[str] = []
        plant.subscribe(k.act_all, lambda key, _p: got.append(key))
        t_end = time.monotonic() + 20.0  # until the subscription has reached the router (load)
        while not got and time.monotonic() < t_end:
            agent.publish(k.act("a"), b"x")
            agent.publish(k.act("b"), b"x")  # not its key: dropped by the router
            time.sleep(0.05)
        time.sleep(0.3)
        assert got and set(got) == {k.act("a")}
    finally:
        for b in buses:
            b.close()
        router.close()


SMALL = """
[run]
name = "tlsrun"
duration_s = 30.0
step_s = 10.0
seed = 3

[controller]
name = "null"

[dispersion]
count = 2
sigma_roe_m = [30.0, 40.0, 30.0, 30.0, 30.0, 30.0]
along_track_spacing_m = 200.0
"""


def test_swarmhil_run_tls(tmp_path: Path) -> None:
    """`swarmhil run --tls`: every process on mutual TLS to the launcher's router."""
    import json
    import subprocess
    import sys

    from conftest import ROOT, read_mcap

    scen = tmp_path / "s.toml"
    scen.write_text(SMALL)
    bad = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(scen), "--tls", "--insecure", "--out",
                          str(tmp_path / "bad")], cwd=ROOT, capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "Traceback" not in bad.stderr
    # the scenario's own [security].tls = true does what --tls does (and --insecure conflicts with it)
    scen.write_text(SMALL + "\n[security]\ntls = true\n")
    bad = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(scen), "--insecure", "--out",
                          str(tmp_path / "bad2")], cwd=ROOT, capture_output=True, text=True)
    assert bad.returncode == 2 and "[security].tls" in bad.stderr and "Traceback" not in bad.stderr, bad.stderr
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(scen), "--no-progress", "--out", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["tls"] is True and s["router"].startswith("tls/127.0.0.1:") and s["steps"] == 3
    assert (out / "secrets" / "tls" / "agent-sc01.pem").is_file()
    assert sum(t == "truth" for t, *_ in read_mcap(out / "run.mcap")) == 4


@pytest.mark.parametrize("table, says", [
    ("[security]\ntls = true\nauth = false\n", "[security].tls needs [security].auth = true"),
    ("[security]\ntls = \"yes\"\n", "[security].tls must be true or false"),
    ("[security]\nauth = 1\n", "[security].auth must be true or false"),
    ("[security]\ncert = \"x\"\n", "cert"),
])
def test_security_table_is_validated(tmp_path: Path, table: str, says: str) -> None:
    from swarmhil.deploy.scenario import ScenarioError, load_scenario

    scen = tmp_path / "s.toml"
    scen.write_text(SMALL + "\n" + table)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(scen)
    assert says in str(exc.value), str(exc.value)


def test_security_defaults_and_resolved_configuration(tmp_path: Path) -> None:
    from swarmhil.deploy.scenario import load_scenario

    scen = tmp_path / "s.toml"
    scen.write_text(SMALL)
    sc = load_scenario(scen)
    assert (sc.auth, sc.tls) == (True, False) and sc.resolved()["security"] == {"auth": True, "tls": False}
    sc = load_scenario(scen, ("security.tls=true",))
    assert sc.tls is True and sc.resolved()["security"]["tls"] is True
