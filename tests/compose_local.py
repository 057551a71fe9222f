"""Run a generated compose project's services as plain processes (no Docker on these machines).

Each service runs its compose `command` with its `environment`, what the container would see:
`${VAR:-default}` interpolated from the given variables, the container paths of its mounts
(`/run/secrets/<target>` of its own secrets only, the scenario `config`, the data volume) mapped
to files of the project directory, `python` the test's interpreter. Services start in
`depends_on` order, a `service_healthy` dependency after the service's own healthcheck command
passes; `prefix` puts a service's process elsewhere (`ip netns exec NS`). Processes are ended by
PID only, die with the test (PR_SET_PDEATHSIG), and run in their own process group.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from conftest import ROOT

_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


def interpolate(value: Any, env: dict[str, str]) -> Any:
    if isinstance(value, str):
        return _VAR.sub(lambda m: env.get(m.group(1)) or (m.group(2) or ""), value)
    if isinstance(value, list):
        return [interpolate(v, env) for v in value]
    if isinstance(value, dict):
        return {k: interpolate(v, env) for k, v in value.items()}
    return value


@dataclass
class Service:
    name: str
    argv: list[str]
    env: dict[str, str]
    health: list[str] | None
    depends: dict[str, str]
    proc: subprocess.Popen | None = None
    log: Any = None
    mounts: dict[str, str] = field(default_factory=dict)


def _map(arg: str, mounts: dict[str, str]) -> str:
    for cpath in sorted(mounts, key=len, reverse=True):
        if arg == cpath or arg.startswith(cpath + "/"):
            return mounts[cpath] + arg[len(cpath):]
    return arg


def services(doc: dict[str, Any], project: Path, variables: dict[str, str], work: Path) -> dict[str, Service]:
    """Every service of the document as a local command (see the module docstring)."""
    doc = interpolate(doc, variables)
    out: dict[str, Service] = {}
    for name, s in doc["services"].items():
        mounts: dict[str, str] = {}
        sdir = work / "secrets" / name  # only this service's secrets, as the container would see them
        sdir.mkdir(parents=True, exist_ok=True)
        for sec in s.get("secrets", []):
            src = project / doc["secrets"][sec["source"]]["file"]
            (sdir / sec["target"]).symlink_to(src.resolve())
        mounts["/run/secrets"] = str(sdir)
        for cfg in s.get("configs", []):
            mounts[cfg["target"]] = str((project / doc["configs"][cfg["source"]]["file"]).resolve())
        for vol in s.get("volumes", []):
            host, cpath = vol.split(":")[:2]
            hp = (project / host).resolve()
            hp.mkdir(parents=True, exist_ok=True)
            mounts[cpath] = str(hp)

        def local(cmd: list[str]) -> list[str]:
            argv = [_map(a, mounts) for a in cmd]
            return [sys.executable if argv[0] == "python" else argv[0], *argv[1:]]
        env = {**os.environ, **{k: str(v) for k, v in s.get("environment", {}).items()}}
        env["PYTHONPATH"] = str(ROOT)
        hc = s.get("healthcheck", {}).get("test")
        dep = s.get("depends_on", {})
        depends = {d: "service_started" for d in dep} if isinstance(dep, list) else {d: c["condition"] for d, c in dep.items()}
        out[name] = Service(name, local(s["command"]), env, local(hc[1:]) if hc else None, depends, mounts=mounts)
    return out


def _die_with_test() -> Any:
    from swarmhil.deploy.launcher import _die_with_parent

    return _die_with_parent(os.getpid())


def start(svcs: dict[str, Service], logs: Path, prefix: dict[str, list[str]] | None = None,
          health_timeout_s: float = 60.0) -> None:
    """Start every service in dependency order (healthchecks honoured)."""
    prefix = prefix or {}
    logs.mkdir(parents=True, exist_ok=True)
    started: set[str] = set()
    while len(started) < len(svcs):
        ready = [s for s in svcs.values() if s.name not in started and set(s.depends) <= started]
        assert ready, f"a dependency cycle among {sorted(set(svcs) - started)}"
        for s in ready:
            for dep, cond in s.depends.items():
                if cond == "service_healthy":
                    _wait_healthy(svcs[dep], prefix.get(dep, []), health_timeout_s)
            s.log = open(logs / f"{s.name}.log", "wb")
            s.proc = subprocess.Popen([*prefix.get(s.name, []), *s.argv], env=s.env, stdout=s.log,
                                      stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, cwd=str(ROOT),
                                      process_group=0, preexec_fn=_die_with_test())
            started.add(s.name)


def _wait_healthy(s: Service, prefix: list[str], timeout_s: float) -> None:
    assert s.health, f"{s.name} has no healthcheck"
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        assert s.proc is not None and s.proc.poll() is None, f"{s.name} exited before it was healthy"
        if subprocess.run([*prefix, *s.health], env=s.env, capture_output=True, cwd=str(ROOT)).returncode == 0:
            return
        time.sleep(0.3)
    raise AssertionError(f"{s.name} not healthy within {timeout_s} s")


def stop(svcs: dict[str, Service], names: list[str], timeout_s: float = 30.0) -> None:
    """SIGTERM (what `docker compose stop` sends), then SIGKILL after timeout_s; by PID only."""
    live = [svcs[n].proc for n in names if svcs[n].proc is not None and svcs[n].proc.poll() is None]
    for p in live:
        os.kill(p.pid, signal.SIGTERM)
    t_end = time.monotonic() + timeout_s
    for p in live:
        try:
            p.wait(max(0.1, t_end - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.kill(p.pid, signal.SIGKILL)
            p.wait()


def run_to_end(svcs: dict[str, Service], logs: Path, prefix: dict[str, list[str]] | None = None,
               timeout_s: float = 400.0, on_started: Any = None) -> dict[str, int]:
    """`docker compose up --exit-code-from plant`: start all, wait for the plant, stop the rest
    (the recorder after the others, the router last). Exit codes by service. `on_started()` is
    called once every service has started."""
    try:
        start(svcs, logs, prefix)
        if on_started:
            on_started()
        svcs["plant"].proc.wait(timeout_s)
    finally:
        others = [n for n in svcs if n not in ("plant", "recorder", "router")]
        stop(svcs, ["plant", *others])
        stop(svcs, ["recorder"])
        stop(svcs, ["router"])
        for s in svcs.values():
            if s.log:
                s.log.close()
    return {n: s.proc.returncode for n, s in svcs.items() if s.proc is not None}


def tail(logs: Path, name: str, n: int = 20) -> str:
    try:
        return "\n".join((logs / f"{name}.log").read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return ""


def require_namespaces() -> None:
    """Root, `ip` and `openssl`: compose services run across network namespaces the test makes
    (each missing one a failure in CI, a skip with the install command elsewhere)."""
    from system_tools import require_command, require_root

    require_root("network namespaces")
    require_command("ip", "iproute2")
    require_command("openssl", "openssl")


def single_host_run(scenario: Path, sc: Any, out: Path, run: str) -> Any:
    """The reference: the same scenario and run id by `swarmhil run`'s launcher, its router on loopback."""
    from swarmhil.deploy.launcher import MultiProcessRun

    res = MultiProcessRun(str(scenario), sc, out, run, progress=False).execute()
    assert res.exit_code == 0, res.reason
    return res
