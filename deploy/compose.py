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
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable

import yaml

from swarmhil.deploy.companions import enabled_companions
from swarmhil.deploy.agent_image import write_resolved_scenario
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


def compose_document(sc: Scenario, run: str, *, image: str = "swarmhil:latest") -> dict[str, Any]:
    """The compose document (paths relative to the project directory write_compose fills)."""
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

    services: dict[str, Any] = {
        "router": svc(["router", "--listen", ROUTER_LISTEN, "--users", f"{SECRETS}/users.txt", "--acl",
                       f"{SECRETS}/acl.json", "--tls", SECRETS],
                      ["users.txt", "acl.json", "tls/ca.pem", "tls/router.pem", "tls/router.key"],
                      restart="unless-stopped",
                      ports=[f"${{SWARMHIL_ROUTER_PUBLISH:-127.0.0.1}}:{ROUTER_PORT}:{ROUTER_PORT}"],
                      healthcheck={"test": ["CMD", "python", "-m", "swarmhil.deploy.proc", "probe", "--router", ROUTER_LISTEN],
                                   "interval": "2s", "timeout": "5s", "retries": 30, "start_period": "5s"}),
        "recorder": client("recorder", "recorder", ["--await-run-end", str(RECORDER_RUN_END_WAIT_S)], restart="no"),
    }
    comps = enabled_companions(sc, {})  # the link channel when the scenario has [link]
    for c in comps:
        services[c.name] = client(c.name, "companion", ["--name", c.name, "--opts", "{}"], restart="on-failure:3")
    for sid in sc.ids:
        services[f"agent-{sid}"] = client(f"agent-{sid}", "agent", ["--id", sid], restart="on-failure:3")
    started = ["recorder", *[c.name for c in comps], *[f"agent-{s}" for s in sc.ids]]
    services["plant"] = client("plant", "plant", ["--companions", ",".join(c.name for c in comps),
                                                  "--barriers", ",".join(c.name for c in comps if c.barrier)],
                               restart="no",
                               depends_on={"router": {"condition": "service_healthy"},
                                           **{s: {"condition": "service_started"} for s in started}})
    return {
        "name": f"swarmhil-{sc.name}".lower(),
        "services": services,
        "networks": {"swarm": {"driver": "bridge", "internal": "${SWARMHIL_INTERNAL:-true}"}},
        "configs": {"scenario": {"file": "./scenario.json"}},
        "secrets": {name: {"file": f"./secrets/{rel}"} for name, rel in sorted(secrets_used.items())},
    }


class _NoAliasDumper(yaml.SafeDumper):
    """Plain YAML: repeated lists written out, no &anchors / *aliases."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def write_compose(sc: Scenario, scenario_file: str, run: str, out: Path, *, router_hosts: Iterable[str] = (),
                  **kw: Any) -> Path:
    """compose.yml, scenario.json and secrets/ (fresh credentials and certificates) in out's directory."""
    from swarmhil.bus.acl import make_run_security  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    d = out.parent
    d.mkdir(parents=True, exist_ok=True)
    (d / "data").mkdir(exist_ok=True)  # the recording's bind mount, owned by the user (not by dockerd)
    write_resolved_scenario(sc, d / "scenario.json")  # the document, and each agent's own config (no pydantic in an agent)
    make_run_security(d, run, users_of(sc), tls=True, tls_hosts=router_hosts)
    doc = compose_document(sc, run, **kw)
    header = (f"# Generated by `swarmhil compose {Path(scenario_file).name}` for run {run}.\n"
              "# Build the image first: docker build -f deploy/Dockerfile -t swarmhil:latest .\n"
              "# Then: SWARMHIL_UID=$(id -u) SWARMHIL_GID=$(id -g) docker compose -f THIS_FILE up --exit-code-from plant\n"
              "# Across hosts: see deploy/compose.py and docs/reliability.md (SWARMHIL_ROUTER, --router-host).\n")
    out.write_text(header + yaml.dump(doc, Dumper=_NoAliasDumper, sort_keys=False))
    return out
