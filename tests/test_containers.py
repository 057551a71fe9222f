"""The generated compose project run in real containers (issue 28): same truth as `swarmhil run`.

As root, with Debian's docker.io and debootstrap (`make setup-system` installs them;
tests/system_tools.py). The test
- uses the Docker engine that answers on the default socket, or starts its own `dockerd` (its PID,
  its own socket and exec root, data root in the cache) with no bridge, no firewall rules, no IP
  forwarding or masquerading, and stops that PID at the end; the host's links, firewall rules and
  forwarding are checked unchanged after;
- makes the base image without a registry (deploy/image.py: `debootstrap --variant=minbase`, then
  `docker import`) and the project image offline (a wheelhouse, `--network none`); the rootfs, the
  wheelhouse and the engine's images are cached in tests/.browser/containers across runs;
- generates the compose project of a short sabatini-20-beacon run (3 agents, the link channel) and
  runs it with Compose v2 as a Docker CLI plugin, every service in the host's network namespace
  (a compose override: `network_mode: host`), so every Zenoh session is on 127.0.0.1 (the network
  rule), as the image's non-root user;
- checks: every container exits 0, the MCAP decodes, and its truth, commands and link deliveries
  equal those of `swarmhil run` of the same scenario and run id, bit for bit.
The durations of each part are printed (`pytest -s`): the first run on a machine is the cold one.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, read_mcap, topics
from system_tools import CACHE, require_command, require_compose, require_root

pytestmark = pytest.mark.system

RUN = "ct1"
SCENARIO = "sabatini-20-beacon.toml"
SETS = ("dispersion.count=3", "run.duration_s=100.0")
STEPS = 10
IMAGE = "swarmhil:test-containers"
BASE = "local/python:3.11-bookworm"
CONTAINERS = CACHE / "containers"
UID = 10001  # the image's user (deploy/Dockerfile)
RUN_DIRS = (Path("/run/docker"), Path("/run/containerd"))  # made by dockerd and containerd whatever their roots


def _host_state() -> dict[str, str]:
    """What a Docker engine may change on the host: links, firewall rules, forwarding, /run."""
    state = {"run": " ".join(str(d) for d in RUN_DIRS if d.exists()), "links": " ".join(sorted(ln.split(":")[1].strip() for ln in subprocess.run(
        ["ip", "-o", "link"], capture_output=True, text=True, check=True).stdout.splitlines())),
        "ip_forward": Path("/proc/sys/net/ipv4/ip_forward").read_text().strip()}
    for tool in ("iptables-save", "ip6tables-save"):
        if shutil.which(tool):
            r = subprocess.run([tool], capture_output=True, text=True)
            state[tool] = "\n".join(ln for ln in r.stdout.splitlines() if not ln.startswith(("#", ":")))
    return state


class Engine:
    """A Docker engine for the test: the one answering on the default socket, or a `dockerd` started here."""

    def __init__(self, dockerd: str, work: Path) -> None:
        d = Path(dockerd).parent  # the client of the engine's package (Debian: /usr/sbin/dockerd, /usr/bin/docker)
        self.cli = next((str(p) for p in (d / "docker", d.parent / "bin" / "docker") if p.exists()), "docker")
        self.proc: subprocess.Popen | None = None
        self.host = "unix:///var/run/docker.sock"
        if self._answers():
            return
        self.made_dirs = [d for d in RUN_DIRS if not d.exists()]
        run_dir = Path(f"/run/swarmhil-docker-{os.getpid()}")  # short: containerd's sockets live under it
        self.run_dir = run_dir
        run_dir.mkdir()
        self.host = f"unix://{run_dir}/docker.sock"
        self.log = work / "dockerd.log"
        (CONTAINERS / "docker").mkdir(parents=True, exist_ok=True)
        self.proc = subprocess.Popen(
            [dockerd, "--host", self.host, "--pidfile", str(run_dir / "docker.pid"), "--exec-root", str(run_dir / "exec"),
             "--data-root", str(CONTAINERS / "docker"), "--bridge=none", "--iptables=false", "--ip-forward=false",
             "--ip-masq=false"], stdout=self.log.open("w"), stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + 60
        while not self._answers():
            assert self.proc.poll() is None and time.monotonic() < deadline, self.log.read_text()[-3000:]
            time.sleep(0.2)

    def _answers(self) -> bool:
        r = subprocess.run([self.cli, "-H", self.host, "version"], capture_output=True, timeout=30)
        return r.returncode == 0

    @property
    def docker(self) -> list[str]:
        return [self.cli, "-H", self.host]

    def close(self) -> None:
        if self.proc is None:
            return
        self.proc.send_signal(signal.SIGTERM)  # dockerd stops its containers and its containerd
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        from swarmhil.deploy.image import mounts_under

        for m in reversed(mounts_under(self.run_dir)):  # dockerd leaves the host's netns bound at exec/netns/default
            subprocess.run(["umount", m], check=True)
        assert not mounts_under(self.run_dir), mounts_under(self.run_dir)  # still mounted: never deleted through
        shutil.rmtree(self.run_dir)
        for d in self.made_dirs:  # the empty state directories dockerd and its containerd make in /run
            for sub, _dirs, _files in sorted(os.walk(d), key=lambda w: -len(w[0])):
                os.rmdir(sub)


def _compose_plugin(compose: list[str], cli: str, cfg: Path) -> list[str]:
    """Compose v2 as a plugin of the Docker client (a private DOCKER_CONFIG: ~/.docker is not touched)."""
    if compose[1:] == ["compose"]:
        return compose
    (cfg / "cli-plugins").mkdir(parents=True)
    (cfg / "cli-plugins" / "docker-compose").symlink_to(compose[0])
    return [cli, "compose"]


def _host_network_override(doc: dict, path: Path) -> Path:
    """Every service in the host's network namespace (no bridge, no published port); compose's `!reset`."""
    lines = ["services:"]
    for name, svc in doc["services"].items():
        lines.append(f"  {name}:\n    network_mode: host\n    networks: !reset []")
        if "ports" in svc:
            lines.append("    ports: !reset []")
    lines.append("networks: !reset {}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _swarmhil(*args: str, env: dict[str, str] | None = None) -> None:
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", *args], cwd=ROOT, capture_output=True, text=True, env=env)
    assert r.returncode == 0, f"swarmhil {' '.join(args)}: {r.stderr[-3000:]}"


def _states(dc: list[str], env: dict[str, str]) -> list[dict]:
    ps = subprocess.run([*dc, "ps", "-a", "--format", "json"], env=env, capture_output=True, text=True, timeout=60)
    assert ps.returncode == 0, ps.stderr
    return [json.loads(ln) for ln in ps.stdout.splitlines() if ln.strip()]


def test_compose_project_in_containers_equals_swarmhil_run(tmp_path: Path) -> None:
    import yaml

    require_root("a container engine")  # each a failure in CI, a skip with the install command elsewhere
    dockerd = require_command("dockerd", "docker.io")
    require_command("debootstrap", "debootstrap")
    require_command("ip", "iproute2")
    compose = require_compose()

    from swarmhil.bus.zenoh_bus import endpoint, free_loopback_port
    from swarmhil.deploy.compose import write_compose
    from swarmhil.deploy.scenario import load_scenario

    sets = [a for s in SETS for a in ("--set", s)]
    single = tmp_path / "single"
    # the containers run with the image's environment, which selects no floating-point kernel set: the
    # reference run neither, or an OPENBLAS_CORETYPE of the host's shell changes its last bits
    from swarmhil.claims.runner import KERNEL_ENV

    plain = {k: v for k, v in os.environ.items() if k not in KERNEL_ENV}
    _swarmhil("run", str(SCENARIOS / SCENARIO), *sets, "--run-id", RUN, "--out", str(single), "--no-progress", env=plain)

    proj = tmp_path / "proj"
    write_compose(load_scenario(SCENARIOS / SCENARIO, SETS), SCENARIO, RUN, proj / "compose.yml")
    doc = yaml.safe_load((proj / "compose.yml").read_text())
    override = _host_network_override(doc, proj / "host-network.yml")
    for p in [proj, *proj.rglob("*")]:  # the 0600 secrets and ./data belong to the containers' user
        os.chown(p, UID, UID)
    ep = endpoint(free_loopback_port(), proto="tls")

    before = _host_state()
    t: dict[str, float] = {}
    t0 = time.monotonic()
    engine = Engine(dockerd, tmp_path)
    try:
        t["engine"] = time.monotonic() - t0
        t0 = time.monotonic()
        denv = {**os.environ, "DOCKER_HOST": engine.host}  # the documented commands (docs/containers.md)
        _swarmhil("image", "base", "--rootfs", str(CONTAINERS / "base-rootfs.tar"), "--tag", BASE, "--docker",
                  engine.cli, env=denv)
        t["base image"] = time.monotonic() - t0
        t0 = time.monotonic()
        _swarmhil("image", "wheelhouse", str(CONTAINERS / "wheelhouse"))
        t["wheelhouse"] = time.monotonic() - t0
        t0 = time.monotonic()
        _swarmhil("image", "build", "--tag", IMAGE, "--base", BASE, "--wheelhouse", str(CONTAINERS / "wheelhouse"),
                  "--docker", engine.cli, env=denv)  # offline: pip --no-index, docker build --network none
        t["project image"] = time.monotonic() - t0

        t0 = time.monotonic()
        dc = [*_compose_plugin(compose, engine.cli, tmp_path / "docker-config"), "-f", str(proj / "compose.yml"),
              "-f", str(override), "-p", f"swarmhil-test-{os.getpid()}"]
        env = {**os.environ, "DOCKER_HOST": engine.host, "DOCKER_CONFIG": str(tmp_path / "docker-config"),
               "SWARMHIL_IMAGE": IMAGE, "SWARMHIL_ROUTER": ep, "SWARMHIL_ROUTER_LISTEN": ep,
               "SWARMHIL_UID": str(UID), "SWARMHIL_GID": str(UID)}
        try:
            up = subprocess.run([*dc, "up", "-d", "--pull", "never"], env=env, capture_output=True, text=True,
                                timeout=300)
            assert up.returncode == 0, up.stderr[-3000:]
            deadline = time.monotonic() + 300
            while True:  # the run ends when the plant exits
                states = _states(dc, env)
                if any(s["Service"] == "plant" and s["State"] == "exited" for s in states) or time.monotonic() > deadline:
                    break
                time.sleep(1)
            # then the rest, like `up --exit-code-from plant` (SIGTERM, dependents first: the router last)
            stop = subprocess.run([*dc, "stop"], env=env, capture_output=True, text=True, timeout=120)
            assert stop.returncode == 0, stop.stderr
            states = _states(dc, env)
            logs = subprocess.run([*dc, "logs", "--no-color"], env=env, capture_output=True, text=True).stdout
        finally:
            subprocess.run([*dc, "down", "--timeout", "10"], env=env, capture_output=True, timeout=120)
        t["compose run"] = time.monotonic() - t0
        print("\ncontainers: " + ", ".join(f"{k} {v:.1f} s" for k, v in t.items()) + f"; total {sum(t.values()):.1f} s")
    finally:
        engine.close()
    assert _host_state() == before  # no link, firewall rule, forwarding or /run directory left behind

    others = {s["Service"]: (s["State"], s["ExitCode"]) for s in states}
    assert len(others) == 1 + 3 + 3 and all(v == ("exited", 0) for v in others.values()), (others, logs[-4000:])
    plant = json.loads((proj / "data" / "plant_summary.json").read_text())
    assert plant["steps"] == STEPS and not plant["dead_agents"] and not plant["missed_deadlines"], plant
    msgs = read_mcap(proj / "data" / "run.mcap")
    assert any(tp == "event" and m.kind == "run_end" for tp, _l, _p, m in msgs)
    counts = {}
    for key in ("truth", "act", "isl/rx/"):
        got = topics(proj / "data" / "run.mcap", key)
        assert got, key
        assert got == topics(single / "run.mcap", key), key
        counts[key] = len(got)
    print(f"containers: equal to swarmhil run, bit for bit: {counts}")
