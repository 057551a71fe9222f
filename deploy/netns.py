"""Emulated hosts as Linux network namespaces (`swarmhil run --hosts K --netns`, deploy/mesh.py).

Host 0 is the launcher's own network namespace; hosts 1 .. K-1 are namespaces the run makes. All K
hosts sit on one Ethernet segment: a bridge in a hub namespace the run makes too, with one veth
link per host (its end in the host, the other end on the bridge), and each host has its own address
10.215.S.(h+1)/24 on its end, S drawn so that the launcher's namespace has no address in that
subnet yet. Between hosts, a router's link to another is real TCP between two addresses; the
processes of host h > 0 run inside its namespace (`ip netns exec`). Needs root and `ip`
(iproute2). `close` deletes the namespaces, which deletes their veth links with them (the end in
the launcher's namespace included).
"""
from __future__ import annotations

import os
import random
import shutil
import socket
import subprocess

SUBNET_PREFIX = "10.215"  # 10.215.S.0/24, S in 1 .. 254
ROUTER_PORT = 7447        # in a host namespace of its own every port is free


class NetnsError(RuntimeError):
    """The namespaces could not be made (not root, no `ip`, or `ip` failed): one line."""


def _ip(*args: str) -> str:
    r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if r.returncode != 0:
        raise NetnsError(f"ip {' '.join(args)}: {r.stderr.strip() or r.returncode}")
    return r.stdout


def check_netns_possible() -> None:
    """NetnsError (one line) when this process cannot make network namespaces."""
    if os.geteuid() != 0:
        raise NetnsError("--netns makes network namespaces and veth links: it needs root")
    if shutil.which("ip") is None:
        raise NetnsError("--netns needs the `ip` command (iproute2)")


def _free_subnet() -> int:
    used = _ip("-4", "-o", "addr", "show")
    free = [s for s in range(1, 255) if f" {SUBNET_PREFIX}.{s}." not in used]
    if not free:
        raise NetnsError(f"no free {SUBNET_PREFIX}.S.0/24 subnet in this namespace")
    return random.choice(free)


class Hosts:
    """K hosts: namespace names (None for host 0, the launcher's), addresses, and the command prefix
    that runs a process on a host."""

    def __init__(self, k: int, tag: str | None = None) -> None:
        check_netns_possible()
        self.tag = tag or f"{os.getpid() % 100000}"
        self.subnet = _free_subnet()
        self.addresses = [f"{SUBNET_PREFIX}.{self.subnet}.{h + 1}" for h in range(k)]
        self.names: list[str | None] = [None] + [f"sw{self.tag}n{h}" for h in range(1, k)]
        self.hub = f"sw{self.tag}hub"
        self._made: list[str] = []
        try:
            self._make(k)
        except BaseException:
            self.close()
            raise

    def _make(self, k: int) -> None:
        for ns in [self.hub, *[n for n in self.names if n]]:
            _ip("netns", "add", ns)
            self._made.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        _ip("-n", self.hub, "link", "add", "br0", "type", "bridge")
        _ip("-n", self.hub, "link", "set", "br0", "up")
        for h in range(k):
            end, bridge_end = f"sw{self.tag}h{h}", f"sw{self.tag}b{h}"
            ns = self.names[h]
            where = ["netns", ns] if ns else []
            _ip("link", "add", end, *where, "type", "veth", "peer", "name", bridge_end, "netns", self.hub)
            _ip("-n", self.hub, "link", "set", bridge_end, "master", "br0", "up")
            pre = ["-n", ns] if ns else []
            _ip(*pre, "addr", "add", f"{self.addresses[h]}/24", "dev", end)
            _ip(*pre, "link", "set", end, "up")

    def prefix(self, host: int) -> list[str]:
        """The command prefix running a process on `host` (none for host 0)."""
        ns = self.names[host]
        return ["ip", "netns", "exec", ns] if ns else []

    def free_port(self, host: int) -> int:
        """A port free on the host's address now (host 0: the launcher's namespace; the others have
        only their own processes, so the usual router port)."""
        if host:
            return ROUTER_PORT
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind((self.addresses[0], 0))
            return int(s.getsockname()[1])

    def pids(self, host: int) -> set[int]:
        """The PIDs running in a host's namespace (host > 0)."""
        return {int(x) for x in _ip("netns", "pids", str(self.names[host])).split()}

    def describe(self) -> list[dict]:
        return [{"address": a, "netns": n} for a, n in zip(self.addresses, self.names)]

    def close(self) -> None:
        for ns in reversed(self._made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)
        self._made.clear()
