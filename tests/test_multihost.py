"""A run across three hosts (issue 17), emulated with Linux network namespaces made by the test.

Hosts: `r` (the router), `p` (plant, recorder, link channel), `a` (the agents), each its own
network namespace with only the addresses the test gives it (10.213.1.0/24 between r and p,
10.213.2.0/24 between r and a; the agents reach the router's 10.213.1.1 through r's other end,
nothing else is routed). The processes are the services of a generated compose project
(`swarmhil compose --router-host 10.213.1.1`, tests/compose_local.py): authenticated by
user/password, access-controlled, on mutual TLS with the run's certificates. The truth, commands
and ISL deliveries must be identical, bit for bit, to the single-host `swarmhil run` of the same
scenario and run id.
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from conftest import SCENARIOS, topics

pytestmark = pytest.mark.system

RUN = "mh1"
SCENARIO = "sabatini-20-beacon.toml"
SETS = ("dispersion.count=4", "run.duration_s=150.0")
ROUTER_IP = "10.213.1.1"
NETS = {"p": ("10.213.1.1", "10.213.1.2"), "a": ("10.213.2.1", "10.213.2.2")}  # (r's end, the host's end)


def _ip(*args: str) -> None:
    r = subprocess.run(["ip", *args], capture_output=True, text=True)
    assert r.returncode == 0, f"ip {' '.join(args)}: {r.stderr}"


class Hosts:
    """Three namespaces and two veth links; `close` deletes them (and so the links)."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 100000}"
        self.ns = {h: f"shmh{tag}{h}" for h in ("r", "p", "a")}
        self.made: list[str] = []
        for ns in self.ns.values():
            _ip("netns", "add", ns)
            self.made.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        for h, (r_addr, h_addr) in NETS.items():
            r_if, h_if = f"mh{tag}{h}r", f"mh{tag}{h}h"
            _ip("link", "add", r_if, "netns", self.ns["r"], "type", "veth", "peer", "name", h_if, "netns", self.ns[h])
            _ip("-n", self.ns["r"], "addr", "add", f"{r_addr}/24", "dev", r_if)
            _ip("-n", self.ns[h], "addr", "add", f"{h_addr}/24", "dev", h_if)
            _ip("-n", self.ns["r"], "link", "set", r_if, "up")
            _ip("-n", self.ns[h], "link", "set", h_if, "up")
            if r_addr != ROUTER_IP:  # the router's address is on the other link: reach it through r
                _ip("-n", self.ns[h], "route", "add", f"{ROUTER_IP}/32", "via", r_addr)

    def prefix(self, host: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns[host]]

    def pids(self, host: str) -> set[int]:
        r = subprocess.run(["ip", "netns", "pids", self.ns[host]], capture_output=True, text=True)
        assert r.returncode == 0, f"ip netns pids {self.ns[host]}: {r.stderr}"
        return {int(x) for x in r.stdout.split()}

    def close(self) -> None:
        for ns in self.made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def _host_of(service: str) -> str:
    if service == "router":
        return "r"
    return "a" if service.startswith("agent-") else "p"


def test_three_host_run_equals_the_single_host_run(tmp_path: Path) -> None:
    import yaml

    from compose_local import require_namespaces, run_to_end, services, single_host_run, tail

    require_namespaces()
    from swarmhil.deploy.compose import write_compose
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(SCENARIOS / SCENARIO, SETS)
    single = single_host_run(SCENARIOS / SCENARIO, sc, tmp_path / "single", RUN)

    out = tmp_path / "proj" / "compose.yml"
    write_compose(sc, SCENARIO, RUN, out, router_hosts=[ROUTER_IP])
    doc = yaml.safe_load(out.read_text())
    ep = f"tls/{ROUTER_IP}:7447"
    svcs = services(doc, out.parent, {"SWARMHIL_ROUTER": ep, "SWARMHIL_ROUTER_LISTEN": ep}, tmp_path / "work")
    logs = tmp_path / "logs"
    hosts = Hosts()
    placed: dict[str, set[int]] = {}
    try:
        prefix = {name: hosts.prefix(_host_of(name)) for name in svcs}

        def where() -> None:  # which namespace each process really runs in
            placed.update({h: hosts.pids(h) for h in ("r", "p", "a")})
        codes = run_to_end(svcs, logs, prefix, on_started=where)
    finally:
        hosts.close()
    assert all(c == 0 for c in codes.values()), {n: (c, tail(logs, n)) for n, c in codes.items() if c}
    for name, s in svcs.items():
        assert s.proc.pid in placed[_host_of(name)], (name, s.proc.pid, placed)
    plant = json.loads((out.parent / "data" / "plant_summary.json").read_text())
    assert plant["steps"] == 15 and not plant["dead_agents"] and not plant["missed_deadlines"], plant
    assert plant["delta_v_total_mps"] > 0  # the agents' commands moved the spacecraft
    multi_mcap, single_mcap = out.parent / "data" / "run.mcap", tmp_path / "single" / "run.mcap"
    for key in ("truth", "act", "isl/rx/"):
        got = topics(multi_mcap, key)
        assert got, key
        assert got == topics(single_mcap, key), key
    assert plant["delta_v_mps"] == single.summary["delta_v_mps"]
