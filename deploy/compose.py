"""Compose file generated from a scenario: the same processes as `swarmhil run`, each agent its own
container (DESIGN.md "Processes"), authenticated, access-controlled and on mutual TLS (issue 17).

`swarmhil compose SCENARIO --out DIR/compose.yml` writes a self-contained project directory:

- `compose.yml`: the services; every path in it is relative to DIR (nothing of the generating
  checkout), and every deployment choice is a variable with a default:
  `SWARMHIL_ROUTER` (the endpoint clients dial, default `tls/router:7447`),
  `SWARMHIL_ROUTER_LISTEN` (the router's own endpoint), `SWARMHIL_ROUTER_PUBLISH` (host address
  the router's port is published on, default 127.0.0.1), `SWARMHIL_INTERNAL` (the bridge network
  has no route out, default true; false when some services run on other hosts),
  `SWARMHIL_IMAGE`, `SWARMHIL_DATA` (the host directory of the recording, default ./data),
  `SWARMHIL_UID`/`SWARMHIL_GID` (the container user, default 10001: set them to the owner of DIR
  so the 0600 secrets and ./data are readable and writable);
- `scenario.json`: the validated scenario, a compose `config`;
- `secrets/`: the run's credentials (bus/acl.py: users.txt, acl.json, one `user:password` per
  process) and TLS files (bus/tls.py: the run's CA, the router's and every process's certificate),
  each mounted as a compose secret into the one service that needs it, under /run/secrets/.

The router is health-checked (`python -m swarmhil.deploy.proc probe`: its TLS port accepts connections)
and every other service waits for it (`depends_on: condition: service_healthy`); the plant starts
last. Restart policies: the router `unless-stopped`; agents and companions `on-failure:3` (a
crash at start-up, e.g. a router not yet reachable from another host, is retried); the recorder
and the plant `no` (a restarted recorder would overwrite run.mcap; a run is one pass). Across
hosts: generate with `--router-host ADDRESS` (the router's certificate then names it), run the
router's host with `SWARMHIL_ROUTER_PUBLISH=ADDRESS SWARMHIL_INTERNAL=false`, the other hosts with
`SWARMHIL_ROUTER=tls/ADDRESS:7447 SWARMHIL_INTERNAL=false docker compose up SERVICE...`.

`swarmhil compose SCENARIO --hosts h1=10.0.0.1,h2=10.0.0.2,... --out DIR` (`write_compose_hosts`)
writes one such project per host instead, DIR/<host>/, each with its own router: the mesh of
`swarmhil run --hosts K` (deploy/mesh.py) for real hosts. Every router dials every other host's
router at the address given (`--connect`, with its Zenoh id and `router-<i>` credential, waiting
for them for ever: the hosts come up in any order); its port is published on its host's address;
the host's agents are clients of their own router; the plant (and so the clock), the recorder and
the companions are on the first host. Placement by `mesh.scenario_placement` (round-robin, or
`[[spacecraft]] host = N`, N counting the hosts in the order given), written to DIR/placement.json
and to each project. One run's security (credentials, ACL naming the routers by Zenoh id, one CA
whose router certificate names every host's address) is made once; each project holds only the
files its own services mount.
"""
from __future__ import annotations

import ipaddress
import json
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import yaml

from swarmhil.bus.keys import check_token
from swarmhil.deploy.companions import enabled_companions
from swarmhil.deploy.agent_image import write_resolved_scenario
from swarmhil.deploy.mesh import GROUND_HOST, new_router_zid, process_hosts, router_name, router_users, scenario_placement
from swarmhil.deploy.scenario import Scenario

ROUTER_PORT = 7447
ROUTER_EP = f"${{SWARMHIL_ROUTER:-tls/router:{ROUTER_PORT}}}"
ROUTER_LISTEN = f"${{SWARMHIL_ROUTER_LISTEN:-tls/router:{ROUTER_PORT}}}"
SECRETS = "/run/secrets"
SCENARIO_IN_CONTAINER = "/etc/swarmhil/scenario.json"
DATA = "/data"
RECORDER_RUN_END_WAIT_S = 20.0


def _secret_name(file: str) -> str:
    return file.replace(".", "_")


def users_of(sc: Scenario) -> list[str]:
    """Every process of the run that opens a session (the launcher's flush handshake is not used)."""
    return ["plant", "recorder", *[c.name for c in enabled_companions(sc, {})], *[f"agent-{s}" for s in sc.ids]]


_DNS_NAME = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*$")
HOSTS_FORM = "NAME[=ADDRESS[:PORT]],... (e.g. h1=10.0.0.1,h2=10.0.0.2)"


@dataclass(frozen=True)
class ComposeHost:
    """One host of a deployment over several hosts: its name (its project's directory), and the
    address and port its router is dialled at by the other hosts' routers."""

    index: int
    name: str
    address: str
    port: int = ROUTER_PORT

    @property
    def endpoint(self) -> str:
        a = f"[{self.address}]" if ":" in self.address else self.address
        return f"tls/{a}:{self.port}"

    @property
    def is_ip(self) -> bool:
        try:
            ipaddress.ip_address(self.address)
        except ValueError:
            return False
        return True


def _address_port(item: str, text: str) -> tuple[str, int]:
    """`ADDRESS[:PORT]` of one `--hosts` entry (an IPv6 address with a port in brackets)."""
    port = ROUTER_PORT
    if text.startswith("["):
        addr, sep, rest = text[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            raise ValueError(f"--hosts {item}: {text} is not [IPV6] or [IPV6]:PORT")
        text, ptext = addr, rest[1:] if rest else None
    elif text.count(":") == 1:
        text, ptext = text.split(":")
    else:
        ptext = None  # a host name, an IPv4 address, or an IPv6 address without a port
    if ptext is not None:
        if not ptext.isdigit() or not 1 <= int(ptext) <= 65535:
            raise ValueError(f"--hosts {item}: port {ptext!r} is not a number in 1 .. 65535")
        port = int(ptext)
    try:
        ip = ipaddress.ip_address(text)
    except ValueError:
        if not _DNS_NAME.match(text):
            raise ValueError(f"--hosts {item}: {text!r} is neither an IP address nor a host name") from None
        return text, port
    if ip.is_unspecified:
        raise ValueError(f"--hosts {item}: {text} is a wildcard address; give the address the other hosts dial")
    return str(ip), port


def parse_hosts(text: str) -> list[ComposeHost]:
    """The hosts of `--hosts NAME[=ADDRESS[:PORT]],...` in order (host 0 first: the ground's).
    A plain NAME is also the address its router is dialled at; PORT defaults to 7447. ValueError
    (one line) for an empty list or entry, a bad name, address or port, a name given twice, or two
    hosts at the same address and port."""
    items = [x.strip() for x in text.split(",")]
    if not any(items):
        raise ValueError(f"--hosts {text!r}: no host given; list them as {HOSTS_FORM}")
    if not all(items):
        raise ValueError(f"--hosts {text}: an empty entry (two commas in a row, or one at an end)")
    out: list[ComposeHost] = []
    for item in items:
        name, sep, addr = (x.strip() for x in item.partition("="))
        if sep and not addr:
            raise ValueError(f"--hosts {item}: no address after '='")
        try:
            check_token(name, "host name")
        except ValueError as exc:
            raise ValueError(f"--hosts {item}: {exc}") from None
        if name.startswith("."):
            raise ValueError(f"--hosts {item}: a host name may not start with '.' (it names the host's project directory)")
        address, port = _address_port(item, addr if sep else name)
        h = ComposeHost(len(out), name, address, port)
        for other in out:
            if other.name == name:
                raise ValueError(f"--hosts: host {name} is given twice")
            if other.endpoint == h.endpoint:
                raise ValueError(f"--hosts: hosts {other.name} and {name} are both at {h.endpoint}")
        out.append(h)
    return out


@dataclass(frozen=True)
class HostPart:
    """What one host's project of a deployment over several hosts runs: its router (its Zenoh id,
    the other routers it dials) and its agents; the ground processes on host 0 only."""

    host: ComposeHost
    hosts: int
    agents: tuple[str, ...]
    zid: str | None
    connect: tuple[str, ...]

    @property
    def ground(self) -> bool:
        return self.host.index == GROUND_HOST


def compose_document(sc: Scenario, run: str, *, image: str = "swarmhil:latest",
                     part: HostPart | None = None) -> dict[str, Any]:
    """The compose document (paths relative to the project directory write_compose fills); with
    `part`, one host's project of a deployment over several hosts (write_compose_hosts)."""
    env = {"OPENBLAS_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    secrets_used: dict[str, str] = {}  # secret name -> file under secrets/

    def secret(rel: str) -> dict[str, str]:
        target = Path(rel).name
        secrets_used[_secret_name(target)] = rel
        return {"source": _secret_name(target), "target": target}

    def svc(cmd: list[str], files: list[str], **extra: Any) -> dict[str, Any]:
        return {"image": f"${{SWARMHIL_IMAGE:-{image}}}", "user": "${SWARMHIL_UID:-10001}:${SWARMHIL_GID:-10001}",
                "command": ["python", "-m", "swarmhil.deploy.proc", *cmd], "environment": dict(env), "networks": ["swarm"],
                "secrets": [secret(f) for f in files], "stop_signal": "SIGTERM", "stop_grace_period": "30s", **extra}

    def client(user: str, role: str, extra_args: list[str], **extra: Any) -> dict[str, Any]:
        args = [role, "--router", ROUTER_EP, "--run", run, "--scenario", SCENARIO_IN_CONTAINER, "--out", DATA,
                "--credentials", f"{SECRETS}/{user}.cred", "--tls", SECRETS, *extra_args]
        files = [f"{user}.cred", "tls/ca.pem", f"tls/{user}.pem", f"tls/{user}.key"]
        extra.setdefault("depends_on", {"router": {"condition": "service_healthy"}})
        return svc(args, files, volumes=[f"${{SWARMHIL_DATA:-./data}}:{DATA}"],
                   configs=[{"source": "scenario", "target": SCENARIO_IN_CONTAINER}], **extra)

    router_cmd = ["router", "--listen", ROUTER_LISTEN, "--users", f"{SECRETS}/users.txt", "--acl", f"{SECRETS}/acl.json",
                  "--tls", SECRETS]
    router_files = ["users.txt", "acl.json", "tls/ca.pem", "tls/router.pem", "tls/router.key"]
    publish, port, internal, name = "${SWARMHIL_ROUTER_PUBLISH:-127.0.0.1}", ROUTER_PORT, "true", f"swarmhil-{sc.name}"
    agents: Iterable[str] = sc.ids
    if part is not None:  # one host of several: its router dials the others' (deploy/mesh.py), its own agents
        if part.connect:
            user = f"router-{part.host.index}"
            router_cmd += ["--zid", str(part.zid), "--credentials", f"{SECRETS}/{user}.cred", "--link-timeout", "0",
                           *[x for ep in part.connect for x in ("--connect", ep)]]
            router_files.append(f"{user}.cred")
        # the port on the host's own address; a host given by name: its address from the operator
        publish = (f"${{SWARMHIL_ROUTER_PUBLISH:-{part.host.address}}}" if part.host.is_ip
                   else "${SWARMHIL_ROUTER_PUBLISH:?set it to this host's IP address}")
        port, internal, agents = part.host.port, "false", part.agents  # the router dials other hosts
        name = f"{name}-{re.sub(r'[^a-z0-9_-]', '-', part.host.name.lower())}"
    services: dict[str, Any] = {
        "router": svc(router_cmd, router_files, restart="unless-stopped",
                      ports=[f"{publish}:{port}:{ROUTER_PORT}"],
                      healthcheck={"test": ["CMD", "python", "-m", "swarmhil.deploy.proc", "probe", "--router", ROUTER_LISTEN],
                                   "interval": "2s", "timeout": "5s", "retries": 30, "start_period": "5s"}),
    }
    comps = enabled_companions(sc, {}) if part is None or part.ground else []  # the link channel when the scenario has [link]
    if part is None or part.ground:
        services["recorder"] = client("recorder", "recorder", ["--await-run-end", str(RECORDER_RUN_END_WAIT_S)], restart="no")
    for c in comps:
        services[c.name] = client(c.name, "companion", ["--name", c.name, "--opts", "{}"], restart="on-failure:3")
    for sid in agents:
        services[f"agent-{sid}"] = client(f"agent-{sid}", "agent", ["--id", sid], restart="on-failure:3")
    if part is None or part.ground:
        started = ["recorder", *[c.name for c in comps], *[f"agent-{s}" for s in agents]]
        services["plant"] = client("plant", "plant", ["--companions", ",".join(c.name for c in comps),
                                                      "--barriers", ",".join(c.name for c in comps if c.barrier)],
                                   restart="no",
                                   depends_on={"router": {"condition": "service_healthy"},
                                               **{s: {"condition": "service_started"} for s in started}})
    return {
        "name": name.lower(),
        "services": services,
        "networks": {"swarm": {"driver": "bridge", "internal": f"${{SWARMHIL_INTERNAL:-{internal}}}"}},
        "configs": {"scenario": {"file": "./scenario.json"}},
        "secrets": {name: {"file": f"./secrets/{rel}"} for name, rel in sorted(secrets_used.items())},
    }


class _NoAliasDumper(yaml.SafeDumper):
    """Plain YAML: repeated lists written out, no &anchors / *aliases."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


BUILD = "# Build the image first: docker build -f deploy/Dockerfile -t swarmhil:latest .\n"


def _write_project(d: Path, sc: Scenario, header: str, doc: dict[str, Any], file: str = "compose.yml") -> Path:
    """A project directory: data/ (the recording's bind mount, owned by the user, not by dockerd),
    scenario.json (the document, and each agent's own config: no pydantic in an agent) and the file."""
    d.mkdir(parents=True, exist_ok=True)
    (d / "data").mkdir(exist_ok=True)
    write_resolved_scenario(sc, d / "scenario.json")
    out = d / file
    out.write_text(header + yaml.dump(doc, Dumper=_NoAliasDumper, sort_keys=False))
    return out


def write_compose(sc: Scenario, scenario_file: str, run: str, out: Path, *, router_hosts: Iterable[str] = (),
                  **kw: Any) -> Path:
    """compose.yml, scenario.json and secrets/ (fresh credentials and certificates) in out's directory."""
    from swarmhil.bus.acl import make_run_security  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    out.parent.mkdir(parents=True, exist_ok=True)
    make_run_security(out.parent, run, users_of(sc), tls=True, tls_hosts=router_hosts)
    header = (f"# Generated by `swarmhil compose {Path(scenario_file).name}` for run {run}.\n" + BUILD +
              "# Then: SWARMHIL_UID=$(id -u) SWARMHIL_GID=$(id -g) docker compose -f THIS_FILE up --exit-code-from plant\n"
              "# Across hosts: see deploy/compose.py and docs/reliability.md (SWARMHIL_ROUTER, --router-host).\n")
    return _write_project(out.parent, sc, header, compose_document(sc, run, **kw), out.name)


PLACEMENT_FILE = "placement.json"


def host_parts(sc: Scenario, hosts: list[ComposeHost]) -> list[HostPart]:
    """Each host's part of the run: the agents `mesh.scenario_placement` puts there, a fresh Zenoh id
    for its router and the other hosts' routers it dials (none for a single host). ValueError (one
    line) for a `[[spacecraft]] host` beyond the hosts given."""
    k = len(hosts)
    where = scenario_placement(sc, k, [h.name for h in hosts])
    zids = [new_router_zid() for _ in hosts] if k > 1 else [None] * k
    return [HostPart(h, k, tuple(s for s in sc.ids if where[s] == h.index), zids[h.index],
                     tuple(o.endpoint for o in hosts if o.index != h.index)) for h in hosts]


def placement_document(sc: Scenario, run: str, parts: list[HostPart]) -> dict[str, Any]:
    """DIR/placement.json: per host its router (endpoint, Zenoh id, the routers it dials), project and
    agents, and `process_hosts` (process name -> host) as in a `swarmhil run --hosts` run.json."""
    ground = ["plant", "recorder", *[c.name for c in enabled_companions(sc, {})]]
    procs = process_hosts({s: p.host.index for p in parts for s in p.agents}, ground)
    procs.update({router_name(p.host.index): p.host.index for p in parts})
    return {"run": run, "scenario": sc.name,
            "hosts": [{"host": p.host.index, "name": p.host.name, "address": p.host.address, "router": p.host.endpoint,
                       "router_process": router_name(p.host.index), "router_zid": p.zid, "connect": list(p.connect),
                       "project": f"{p.host.name}/compose.yml", "agents": list(p.agents),
                       "ground": ground if p.ground else []} for p in parts],
            "process_hosts": dict(sorted(procs.items()))}


def _copy_private(src: Path, root: Path, rel: Path) -> None:
    """One secret into a host's project, root/rel: its directories 0700, the file 0600 (bus/acl.py, bus/tls.py)."""
    d = root
    for sub in ("", *rel.parent.parts):
        d = d / sub
        d.mkdir(mode=0o700, parents=True, exist_ok=True)
        os.chmod(d, 0o700)
    shutil.copyfile(src, root / rel)
    os.chmod(root / rel, 0o600)


def write_compose_hosts(sc: Scenario, scenario_file: str, run: str, out: Path, hosts: list[ComposeHost],
                        **kw: Any) -> dict[str, Any]:
    """One project per host, DIR/<name>/ (compose.yml, scenario.json, secrets/, data/,
    placement.json), and DIR/placement.json (see the module docstring); returns the placement.
    ValueError (one line, nothing written) for a placement beyond the hosts or a DIR not empty."""
    from swarmhil.bus.acl import make_run_security  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    parts = host_parts(sc, hosts)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ValueError(f"--out {out}: {'not a directory' if not out.is_dir() else 'not empty'}; give a new directory "
                         "(one project per host is written under it)")
    placed = placement_document(sc, run, parts)
    users = [*users_of(sc), *router_users(len(hosts), first=0)] if len(hosts) > 1 else users_of(sc)
    out.mkdir(parents=True, exist_ok=True)
    made = Path(tempfile.mkdtemp(prefix=".run-", dir=out))  # the run's security, once; each host gets its part
    try:
        make_run_security(made, run, users, tls=True, tls_hosts=[h.address for h in hosts],
                          router_zids=[p.zid for p in parts if p.zid])
        for p in parts:
            doc = compose_document(sc, run, part=p, **kw)
            d = out / p.host.name
            for sec in doc["secrets"].values():
                rel = Path(sec["file"]).relative_to("secrets")
                _copy_private(made / "secrets" / rel, d / "secrets", rel)
            others = ", ".join(f"{o.name} at {o.endpoint}" for o in hosts if o.index != p.host.index) or "none"
            header = (f"# Generated by `swarmhil compose {Path(scenario_file).name} --hosts ...` for run {run}: host "
                      f"{p.host.name} ({p.host.index} of 0 .. {len(hosts) - 1}), {len(p.agents)} agents"
                      f"{', the plant, recorder and companions' if p.ground else ''}.\n"
                      f"# Its router is dialled at {p.host.endpoint} and dials the other hosts' routers: {others}.\n" + BUILD +
                      "# Then on this host: SWARMHIL_UID=$(id -u) SWARMHIL_GID=$(id -g) docker compose -f THIS_FILE up "
                      f"{'--exit-code-from plant' if p.ground else '-d'}\n"
                      f"# See ../{PLACEMENT_FILE} and docs/scaling.md \"Compose projects over several hosts\".\n")
            _write_project(d, sc, header, doc)
            (d / PLACEMENT_FILE).write_text(json.dumps(placed, indent=1) + "\n")
    finally:
        shutil.rmtree(made, ignore_errors=True)
    (out / PLACEMENT_FILE).write_text(json.dumps(placed, indent=1) + "\n")
    return placed
