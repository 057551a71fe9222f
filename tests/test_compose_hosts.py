"""`swarmhil compose SCENARIO --hosts h1,h2,h3 --out DIR`: one compose project per host, each with its
own router, the routers a mesh (deploy/compose.py `write_compose_hosts`, deploy/mesh.py).

The projects as files: every router dials exactly the other hosts' routers, every agent is on
exactly one host by the rule `swarmhil run --hosts` uses, the ground processes on the first host,
each project holds the secrets its services mount and nothing else, one CA and one ACL for the run.
Bad `--hosts` input: one line, exit 2, nothing written. And (system) the three generated projects
run as plain processes (tests/compose_local.py), each host a network namespace with its own
address (deploy/netns.py), only the router and client addresses set to the hosts' own: the routers
link as a mesh over real TCP on mutual TLS and the run's truth equals `swarmhil run`'s bit for bit.
"""
from __future__ import annotations

import json
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import ROOT, SCENARIOS, topics
from swarmhil.deploy.mesh import scenario_placement
from swarmhil.deploy.scenario import load_scenario

HOSTS = "h1=10.0.0.1,h2=10.0.0.2:7500,h3"
ENDPOINTS = {"h1": "tls/10.0.0.1:7447", "h2": "tls/10.0.0.2:7500", "h3": "tls/h3:7447"}
PINS = ("spacecraft.0.host=2", "spacecraft.4.host=1")  # sc01 on h3, sc05 on h2; the rest round-robin


def _compose(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "compose", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)


def _arg(cmd: list[str], opt: str) -> list[str]:
    """Every value of a repeatable option in a command line."""
    return [cmd[i + 1] for i, a in enumerate(cmd) if a == opt]


def _projects(out: Path) -> dict[str, dict]:
    return {h: yaml.safe_load((out / h / "compose.yml").read_text()) for h in ENDPOINTS}


def test_per_host_projects_place_every_agent_once_and_mesh_their_routers(tmp_path: Path) -> None:
    out = tmp_path / "deploy"
    sets = [a for s in PINS for a in ("--set", s)]
    r = _compose(str(SCENARIOS / "sabatini-20-explicit.toml"), "--hosts", HOSTS, "--out", str(out), "--run-id", "ch1", *sets)
    assert r.returncode == 0, r.stderr
    docs = _projects(out)
    placed = json.loads((out / "placement.json").read_text())
    sc = load_scenario(SCENARIOS / "sabatini-20-explicit.toml", PINS)
    rule = scenario_placement(sc, 3)  # the rule of `swarmhil run --hosts 3`
    assert rule["sc01"] == 2 and rule["sc05"] == 1 and rule["sc02"] == 1 and rule["sc04"] == 0

    names = list(ENDPOINTS)
    seen: dict[str, str] = {}
    for i, (h, doc) in enumerate(docs.items()):
        svcs = doc["services"]
        router = svcs["router"]["command"]
        # the router dials exactly the other hosts' routers, at the addresses given, as its own router-<i>
        assert _arg(router, "--connect") == [ENDPOINTS[o] for o in names if o != h], (h, router)
        assert _arg(router, "--zid") == [placed["hosts"][i]["router_zid"]]
        assert _arg(router, "--credentials") == [f"/run/secrets/router-{i}.cred"]
        assert _arg(router, "--link-timeout") == ["0"]  # the hosts come up in any order
        assert _arg(router, "--tls") == ["/run/secrets"] and _arg(router, "--acl") == ["/run/secrets/acl.json"]
        port = ENDPOINTS[h].rsplit(":", 1)[1]
        publish = svcs["router"]["ports"][0]
        assert publish.endswith(f":{port}:7447"), publish
        assert publish.startswith("${SWARMHIL_ROUTER_PUBLISH:?") if h == "h3" else f":-10.0.0.{i + 1}}}" in publish
        assert doc["networks"]["swarm"]["internal"] == "${SWARMHIL_INTERNAL:-false}"  # the router dials out
        agents = [s[len("agent-"):] for s in svcs if s.startswith("agent-")]
        assert agents == placed["hosts"][i]["agents"] == [s for s in sc.ids if rule[s] == i], h
        for sid in agents:
            assert sid not in seen, (sid, seen[sid], h)  # on exactly one host
            seen[sid] = h
            cmd = svcs[f"agent-{sid}"]["command"]
            assert _arg(cmd, "--router") == ["${SWARMHIL_ROUTER:-tls/router:7447}"]  # its own host's router
        ground = {s for s in svcs if s != "router" and not s.startswith("agent-")}
        assert ground == ({"plant", "recorder"} if i == 0 else set()), (h, ground)  # the plant is the clock
        if i == 0:
            assert set(svcs["plant"]["depends_on"]) == {"router", "recorder", *[f"agent-{s}" for s in agents]}
    assert sorted(seen) == sorted(sc.ids)  # every spacecraft placed
    assert len({d["name"] for d in docs.values()}) == 3  # three projects can share one engine
    assert placed["process_hosts"]["plant"] == placed["process_hosts"]["recorder"] == 0
    assert {k: v for k, v in placed["process_hosts"].items() if k.startswith("agent-")} == {f"agent-{s}": h for s, h in rule.items()}
    assert [h["router"] for h in placed["hosts"]] == list(ENDPOINTS.values())

    # the run's security: made once, each project holding exactly what its services mount
    zids = {h["router_zid"] for h in placed["hosts"]}
    for i, h in enumerate(names):
        proj, doc = out / h, docs[h]
        assert json.loads((proj / "placement.json").read_text()) == placed
        used = {(proj / s["file"]).resolve() for s in doc["secrets"].values()}
        present = {p.resolve() for p in (proj / "secrets").rglob("*") if p.is_file()}
        assert used == present, (h, sorted(map(str, used ^ present)))
        for name, svc in doc["services"].items():
            for s in svc["secrets"]:
                assert s["source"] in doc["secrets"], (h, name, s)
        for f in present:
            assert stat.S_IMODE(f.stat().st_mode) == 0o600, f
        for d in (proj / "secrets", proj / "secrets" / "tls"):
            assert stat.S_IMODE(d.stat().st_mode) == 0o700, d
        assert not (proj / "secrets" / "tls" / "ca.key").exists()
        acl = json.loads((proj / "secrets" / "acl.json").read_text())
        mesh = next(s for s in acl["subjects"] if s["id"] == "mesh-routers")
        assert set(mesh["zids"]) == zids and mesh["cert_common_names"] == ["router"]
        users = dict(line.split(":", 1) for line in (proj / "secrets" / "users.txt").read_text().split())
        mine = (proj / "secrets" / f"router-{i}.cred").read_text().strip()
        assert users[f"router-{i}"] == mine.split(":", 1)[1]
        for sid in placed["hosts"][i]["agents"]:
            user, pw = (proj / "secrets" / f"agent-{sid}.cred").read_text().strip().split(":", 1)
            assert users[user] == pw
    for rel in ("secrets/tls/ca.pem", "secrets/users.txt", "secrets/acl.json", "secrets/tls/router.pem"):
        assert len({(out / h / rel).read_bytes() for h in names}) == 1, rel  # one CA, one ACL for the run
    san = subprocess.run(["openssl", "x509", "-noout", "-ext", "subjectAltName", "-in", str(out / "h1" / "secrets" / "tls" / "router.pem")],
                         capture_output=True, text=True)
    for name in ("IP Address:10.0.0.1", "IP Address:10.0.0.2", "DNS:h3"):
        assert name in san.stdout, san.stdout + san.stderr  # every host's router is dialled at its address


def test_the_first_host_holds_the_companions(tmp_path: Path) -> None:
    out = tmp_path / "d"
    r = _compose(str(SCENARIOS / "sabatini-20-beacon.toml"), "--hosts", "a,b", "--out", str(out), "--run-id", "ch2",
                 "--set", "dispersion.count=5")
    assert r.returncode == 0, r.stderr
    a, b = (yaml.safe_load((out / h / "compose.yml").read_text())["services"] for h in ("a", "b"))
    assert {"plant", "recorder", "channel"} <= set(a) and not {"plant", "recorder", "channel"} & set(b)
    cmd = a["plant"]["command"]
    assert _arg(cmd, "--barriers") == ["channel"]
    assert [s for s in a if s.startswith("agent-")] == ["agent-sc01", "agent-sc03", "agent-sc05"]
    assert [s for s in b if s.startswith("agent-")] == ["agent-sc02", "agent-sc04"]


def test_per_host_projects_validate_with_compose_v2(tmp_path: Path) -> None:
    """The real Compose v2 binary (tests/system_tools.py; skipped without one, as in test_compose.py)
    reads each project; a host given by name needs SWARMHIL_ROUTER_PUBLISH (its IP address)."""
    import os

    from system_tools import require_compose

    exe = require_compose()
    out = tmp_path / "d"
    r = _compose(str(SCENARIOS / "sabatini-20-beacon.toml"), "--hosts", "a=10.0.0.1,b=10.0.0.2:7500,c",
                 "--out", str(out), "--run-id", "ch3", "--set", "dispersion.count=4")
    assert r.returncode == 0, r.stderr
    env = {k: v for k, v in os.environ.items() if not k.startswith("SWARMHIL_")}
    for h, port, n in (("a", "7447", 4 + 2), ("b", "7500", 1 + 1), ("c", "7447", 1 + 1)):  # router, ground, agents
        f = out / h / "compose.yml"
        cfg = subprocess.run([*exe, "-f", str(f), "config", "--format", "json"], capture_output=True, text=True,
                             cwd=tmp_path, env=env if h != "c" else {**env, "SWARMHIL_ROUTER_PUBLISH": "10.0.0.3"})
        assert cfg.returncode == 0, (h, cfg.stderr)
        doc = json.loads(cfg.stdout)
        assert len(doc["services"]) == n, (h, sorted(doc["services"]))
        published = doc["services"]["router"]["ports"][0]
        assert (published["host_ip"], published["published"], published["target"]) == (
            {"a": "10.0.0.1", "b": "10.0.0.2", "c": "10.0.0.3"}[h], port, 7447), published
        assert not doc["networks"]["swarm"].get("internal", False)
    bare = subprocess.run([*exe, "-f", str(out / "c" / "compose.yml"), "config", "-q"], capture_output=True, text=True,
                          cwd=tmp_path, env=env)
    assert bare.returncode != 0 and "SWARMHIL_ROUTER_PUBLISH" in bare.stderr, bare.stderr


@pytest.mark.parametrize(("hosts", "needle"), [
    ("", "no host given"),
    (" , ", "no host given"),
    ("h1,,h2", "an empty entry"),
    ("h1,h2,h1", "host h1 is given twice"),
    ("a=10.0.0.1,b=10.0.0.1", "hosts a and b are both at tls/10.0.0.1:7447"),
    ("a=0.0.0.0,b", "a wildcard address"),
    ("a=10.0.0.1:0,b", "not a number in 1 .. 65535"),
    ("a=,b", "no address after '='"),
    ("a/b", "invalid host name"),
    ("..,b", "may not start with '.'"),
    ("a=not_a_host!", "neither an IP address nor a host name"),
])
def test_bad_hosts_are_one_line_and_exit_2(tmp_path: Path, hosts: str, needle: str) -> None:
    out = tmp_path / "d"
    r = _compose(str(SCENARIOS / "sabatini-20.toml"), "--hosts", hosts, "--out", str(out))
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert r.returncode == 2 and len(lines) == 1 and needle in lines[0], (hosts, r.returncode, r.stderr)
    assert not out.exists()


def test_a_spacecraft_on_an_unknown_host_and_other_misuse_exit_2(tmp_path: Path) -> None:
    explicit = str(SCENARIOS / "sabatini-20-explicit.toml")
    cases = [
        ((explicit, "--hosts", "h1,h2,h3", "--set", "spacecraft.6.host=3", "--out", str(tmp_path / "d")),
         "[[spacecraft]] sc07: host = 3, but --hosts names 3 hosts, numbered in the order given: 0 = h1, 1 = h2, 2 = h3"),
        ((explicit, "--hosts", "h1,h2", "--out", str(tmp_path / "d" / "compose.yml")), "give --out DIR"),
        ((explicit, "--hosts", "h1,h2"), "give --out DIR"),
        ((explicit, "--hosts", "h1,h2", "--router-host", "10.0.0.9", "--out", str(tmp_path / "d")), "--router-host and --hosts"),
    ]
    for args, needle in cases:
        r = _compose(*args)
        lines = [x for x in r.stderr.splitlines() if x.strip()]
        assert r.returncode == 2 and len(lines) == 1 and needle in lines[0], (args, r.returncode, r.stderr)
        assert not (tmp_path / "d").exists()
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("an earlier project\n")
    r = _compose(explicit, "--hosts", "h1,h2", "--out", str(full))
    assert r.returncode == 2 and "not empty" in r.stderr and sorted(p.name for p in full.iterdir()) == ["keep.txt"]


RUN = "chm1"
SCENARIO = "sabatini-20-beacon.toml"
SETS = ("dispersion.count=6", "run.duration_s=100.0")


@pytest.mark.system
def test_three_host_projects_run_as_a_mesh_and_equal_the_single_host_run(tmp_path: Path) -> None:
    """Each host a network namespace (hosts 1..3 of deploy/netns.Hosts, on one bridge); each host's
    project's services as processes in it; variables set only to the host's own address (its router
    listens there, its clients dial it: in a container the router listens on the compose network and
    its port is published there). The routers' --connect endpoints are the generated ones."""
    from compose_local import require_namespaces, services, single_host_run, start, stop, tail

    require_namespaces()
    from swarmhil.deploy.compose import parse_hosts, write_compose_hosts
    from swarmhil.deploy.netns import Hosts

    sc = load_scenario(SCENARIOS / SCENARIO, SETS)
    single_host_run(SCENARIOS / SCENARIO, sc, tmp_path / "single", RUN)

    net = Hosts(4)  # host 0 is this namespace: unused; the three compose hosts are namespaces 1 .. 3
    svcs: dict[str, dict] = {}
    placed_pids: dict[str, set[int]] = {}
    try:
        hosts = parse_hosts(",".join(f"h{i}={net.addresses[i]}" for i in (1, 2, 3)))
        out = tmp_path / "deploy"
        placed = write_compose_hosts(sc, SCENARIO, RUN, out, hosts)
        prefix = {h.name: net.prefix(h.index + 1) for h in hosts}
        for h in hosts:
            doc = yaml.safe_load((out / h.name / "compose.yml").read_text())
            ep = h.endpoint  # the generated address of this host's router
            svcs[h.name] = services(doc, out / h.name, {"SWARMHIL_ROUTER": ep, "SWARMHIL_ROUTER_LISTEN": ep},
                                    tmp_path / "work" / h.name)
        try:
            for name in ("h3", "h1", "h2"):  # any order: the plant waits for every agent, the routers dial on
                start(svcs[name], tmp_path / "logs" / name, dict.fromkeys(svcs[name], prefix[name]))
            placed_pids.update({h.name: net.pids(h.index + 1) for h in hosts})
            svcs["h1"]["plant"].proc.wait(300)
        finally:
            for name, s in svcs.items():
                stop(s, [n for n in s if n not in ("router", "recorder")])
            stop(svcs["h1"], ["recorder"])
            for s in svcs.values():
                stop(s, ["router"])
                for x in s.values():
                    if x.log:
                        x.log.close()
    finally:
        net.close()
    codes = {f"{h}/{n}": x.proc.returncode for h, s in svcs.items() for n, x in s.items()}
    assert all(c == 0 for c in codes.values()), {n: (c, tail(tmp_path / "logs" / n.split("/")[0], n.split("/")[1]))
                                                  for n, c in codes.items() if c}
    for h, s in svcs.items():
        for n, x in s.items():
            assert x.proc.pid in placed_pids[h], (h, n)  # every process in its host's namespace
        log = (tmp_path / "logs" / h / "router.log").read_text(errors="replace")
        assert "router mesh: linked to 2 routers" in log, log  # each router linked to both others
    assert sorted(n for s in svcs.values() for n in s if n.startswith("agent-")) == [f"agent-{i}" for i in sc.ids]
    assert [len(h["agents"]) for h in placed["hosts"]] == [2, 2, 2]
    data = out / "h1" / "data"
    plant = json.loads((data / "plant_summary.json").read_text())
    assert plant["steps"] == 10 and not plant["dead_agents"] and not plant["missed_deadlines"], plant
    assert plant["delta_v_total_mps"] > 0  # commands from every host reached the plant
    for key in ("truth", "act", "isl/rx/"):
        got = topics(data / "run.mcap", key)
        assert got, key
        assert got == topics(tmp_path / "single" / "run.mcap", key), key
