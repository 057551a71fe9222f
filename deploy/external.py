"""External flight software (issue 26, docs/hil.md): a spacecraft whose flight software the
launcher does not start.

A `[[spacecraft]]` table with `fsw = "external"` names it. The launcher starts everything else,
writes a join kit for it in `DIR/external/<id>/` (`write_join_kit`), prints one line saying where
the kit is and what it waits for, and waits up to the spacecraft's `join_timeout_s` for its
liveliness token `swarm/<run>/alive/agent-<id>` (`JoinWatch`). From then on the external flight
software is an agent like any other: the plant sends it its stimuli, waits for its command
(lockstep) or counts its misses (real time), and marks it dead when its token goes; the router's
access control and credentials (bus/acl.py) are the built-in agent's.

The kit holds everything a client that imports nothing of the project needs:

- `join.json`: run id, router endpoint(s), the spacecraft's key expressions and message types,
  step period, mode and deadlines, the Zenoh client settings (credential and TLS files included),
  and the built-in agent's configuration of this spacecraft (controller, gains, orbit);
- `swarmhil.proto` and `keys.json` (bus/): the messages and the key -> type map;
- `agent-<id>.cred` (user:password) when the run authenticates, and `tls/` (the run's CA, this
  agent's client certificate and key) when it runs on mutual TLS.

File names inside join.json are relative to the kit directory, except the `zenoh` block's TLS
files, which are absolute (the block works as given from any working directory; a kit copied to
another machine resolves `tls` against its own directory). The kit holds a secret: the directory
is 0700 and every file 0600, like the run's `secrets/`.
"""
from __future__ import annotations

import json
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any

from swarmhil.bus.codec import message_type_of_topic
from swarmhil.bus.keys import Keys
from swarmhil.deploy.agent_image import agent_config

DEFAULT_JOIN_TIMEOUT_S = 300.0
KIT_VERSION = 1
BUS_DIR = Path(__file__).resolve().parent.parent / "bus"
# an external agent's Zenoh lease, as a built-in agent's (deploy/proc.py AGENT_LEASE_MS): a frozen
# flight computer's token goes after this long
LEASE_MS = 5000
CONNECT_TIMEOUT_MS = 15000


class JoinTimeout(RuntimeError):
    """An external flight software did not join within its join timeout."""


def external_ids(sc: Any) -> list[str]:
    """Spacecraft of the scenario whose flight software joins from outside (`fsw = "external"`)."""
    return [s.id for s in sc.spacecraft if getattr(s, "fsw", "builtin") == "external"]


def join_timeout_s(sc: Any, sid: str) -> float:
    t = sc.spec(sid).join_timeout_s
    return DEFAULT_JOIN_TIMEOUT_S if t is None else float(t)


def plant_ready_timeout_s(sc: Any, default_s: float = 600.0) -> float:
    """How long the plant waits for every process before step 0: its default, or longer than the
    longest join timeout (the launcher, not the plant, says which external agent did not join)."""
    return max([default_s, *(join_timeout_s(sc, s) + 60.0 for s in external_ids(sc))])


def deadlines(sc: Any) -> dict[str, Any]:
    """When the plant needs the command of step k (plant/pacing.py), in words and numbers."""
    if sc.mode == "lockstep":
        return {"mode": "lockstep", "stall_timeout_s": sc.stall_timeout_s,
                "rule": "the plant waits for the command of step k however long it takes; a step still open "
                        "after stall_timeout_s of wall time drops this spacecraft (dead, it coasts)"}
    period = sc.step_s / sc.speed
    return {"mode": "realtime", "wall_period_s": period,
            "rule": "the command of step k must reach the plant before the wall time t0 + (k+1) * wall_period_s "
                    "(t0: the plant's start); a late or missing command is a missed deadline, counted, and the "
                    "previous command is held for the step"}


def _message_types(keys: dict[str, str]) -> dict[str, str | None]:

    out = {}
    for name, key in keys.items():
        cls = message_type_of_topic(key)
        out[name] = None if cls is None else cls.DESCRIPTOR.full_name
    return out


def _write(path: Path, text: str | bytes) -> None:
    data = text.encode() if isinstance(text, str) else text
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(path, 0o600)


def join_document(sc: Any, run: str, sid: str, router: list[str], credential: Any, tls_files: dict[str, str] | None,
                  agent_cfg: dict[str, Any], kit_dir: Path | None = None) -> dict[str, Any]:
    """join.json of spacecraft `sid`. File names in `credential`, `tls`, `proto` and `keys_json` are
    relative to the kit directory (a kit copied elsewhere still finds them); the `zenoh` block's TLS
    files are absolute paths in `kit_dir` (the kit where it was written), so the block works as
    given from any working directory."""
    k = Keys(run)
    user = f"agent-{sid}"
    keys = {"sense": k.sense(sid, sc.sensing["kind"]), "act": k.act(sid), "tm": k.tm(sid), "isl_tx": k.isl_tx(sid),
            "isl_rx": k.isl_rx(sid), "alive": k.alive(user)}
    zenoh_cfg: dict[str, Any] = {
        "mode": "client", "connect/endpoints": list(router), "listen/endpoints": [],
        "scouting/multicast/enabled": False, "scouting/gossip/enabled": False,
        "connect/timeout_ms": CONNECT_TIMEOUT_MS, "transport/link/tx/lease": LEASE_MS}
    if credential is not None:
        zenoh_cfg.update({"transport/auth/usrpwd/user": credential.user,
                          "transport/auth/usrpwd/password": credential.password})
    if tls_files is not None:
        at = (lambda name: str(kit_dir / name)) if kit_dir is not None else (lambda name: name)
        zenoh_cfg.update({"transport/link/tls/root_ca_certificate": at(tls_files["ca"]),
                          "transport/link/tls/connect_certificate": at(tls_files["cert"]),
                          "transport/link/tls/connect_private_key": at(tls_files["key"]),
                          "transport/link/tls/enable_mtls": True})
    return {
        "kit_version": KIT_VERSION,
        "run": run,
        "spacecraft": sid,
        "process": user,
        "router": list(router),
        "join_timeout_s": join_timeout_s(sc, sid),
        "keys": keys,
        "message_types": _message_types(keys),
        "publishes": ["act", "tm", "isl_tx"],
        "subscribes": ["sense", "isl_rx"],
        "liveliness_token": keys["alive"],
        "timing": {"mode": sc.mode, "step_s": sc.step_s, "steps": sc.steps, "speed": sc.speed,
                   "decision_period_steps": sc.decision_period_steps, "deadline": deadlines(sc)},
        "answer": ("for each stimulus on keys.sense (header.step = k), publish one ActuatorCommand on keys.act with "
                   "header.run = run, header.source = spacecraft, header.step = k, header.t = the stimulus's t, "
                   "accel_mps2 (LVLH, held over the step) and a non-empty controller name; isl_tx_count = the "
                   "IslPackets sent on keys.isl_tx in step k before it. Telemetry on keys.tm is optional."),
        "credential": None if credential is None else f"{user}.cred",
        "tls": tls_files,
        "zenoh": zenoh_cfg,
        "paths_relative_to": "this directory (credential, tls, proto, keys_json); the zenoh block's TLS files are "
                             "absolute paths of the kit where it was written: a copied kit resolves `tls` against its "
                             "own directory instead",
        "proto": "swarmhil.proto",
        "keys_json": "keys.json",
        "agent": agent_cfg,
    }


def write_join_kit(out: Path, sc: Any, run: str, sid: str, router: list[str], security: Any) -> Path:
    """DIR/external/<sid>/ (see the module docstring); returns the directory. join.json is written
    last, by rename, so a watcher that sees it sees a complete kit."""

    kit = out / "external" / sid
    kit.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(kit, 0o700)
    for name in ("swarmhil.proto", "keys.json"):
        _write(kit / name, (BUS_DIR / name).read_bytes())
    user = f"agent-{sid}"
    credential, tls_files = None, None
    if security is not None:
        credential = security.credential(user)
        shutil.copyfile(security.credentials[user], kit / f"{user}.cred")
        os.chmod(kit / f"{user}.cred", 0o600)
        if security.tls is not None:
            (kit / "tls").mkdir(mode=0o700, exist_ok=True)
            tls_files = {}
            for role, name in (("ca", "ca.pem"), ("cert", f"{user}.pem"), ("key", f"{user}.key")):
                _write(kit / "tls" / name, (security.tls.dir / name).read_bytes())
                tls_files[role] = f"tls/{name}"
    doc = join_document(sc, run, sid, router, credential, tls_files, agent_config(sc, sid), kit.resolve())
    _write(kit / "join.json.tmp", json.dumps(doc, indent=1) + "\n")
    (kit / "join.json.tmp").replace(kit / "join.json")
    return kit


def join_hosts(join_listen: str | None) -> list[str]:
    """The host of a `--join-listen` endpoint (`tls/10.0.0.1:7447` -> ["10.0.0.1"]): the run's router
    certificate must name it (bus/tls.py)."""
    if not join_listen:
        return []
    return [join_listen.split("/", 1)[1].rpartition(":")[0].strip("[]")]


def check_join_listen(endpoint: str, tls: bool, sc: Any) -> None:
    """ValueError (one line) for a `--join-listen` that cannot work: no external spacecraft, another
    protocol than the run's (tcp/, or tls/ with --tls), no host:port, or a wildcard address."""
    proto = "tls" if tls else "tcp"
    if not external_ids(sc):
        raise ValueError(f"--join-listen {endpoint}: the scenario has no spacecraft with fsw = \"external\"")
    head, _, rest = endpoint.partition("/")
    host, _, port = rest.rpartition(":")
    if head != proto or not host or not port.isdigit():
        raise ValueError(f"--join-listen {endpoint}: must be {proto}/ADDRESS:PORT (the run's router speaks {proto})")
    if host.strip("[]") in ("0.0.0.0", "::", ""):
        raise ValueError(f"--join-listen {endpoint}: a wildcard address; give the address of the interface to listen on")


class JoinWatch:
    """The launcher's wait for the external agents' liveliness tokens (on its own Zenoh session)."""

    def __init__(self, bus: Any, run: str, ids: list[str], timeouts_s: dict[str, float]) -> None:
        self.keys = Keys(run)
        self.ids = list(ids)
        self.timeouts_s = timeouts_s
        self.t0 = time.monotonic()
        self.joined: dict[str, float] = {}  # id -> seconds after the kits were written (first token)
        self.present: set[str] = set()      # ids whose token is up now
        self._lock = threading.Lock()
        for sid in self.ids:
            bus.watch_liveliness(self.keys.alive(f"agent-{sid}"), self._on_token)

    def _on_token(self, key: str, alive: bool) -> None:
        sid = key.rsplit("/", 1)[-1][len("agent-"):]
        with self._lock:
            if alive:
                self.present.add(sid)
                self.joined.setdefault(sid, time.monotonic() - self.t0)
            else:
                self.present.discard(sid)

    def check(self, router: str) -> None:
        """Before step 0: JoinTimeout (one line naming the spacecraft and the endpoint) once a join
        timeout has passed without that spacecraft's token up (never joined, or joined and left)."""
        now = time.monotonic() - self.t0
        with self._lock:
            late = [s for s in self.ids if s not in self.present and now > self.timeouts_s[s]]
        if late:
            sid = late[0]
            raise JoinTimeout(f"external flight software of spacecraft {sid} did not join within "
                              f"{self.timeouts_s[sid]:g} s: no liveliness token {self.keys.alive('agent-' + sid)} "
                              f"at {router}")

    def summary(self) -> dict[str, Any]:
        with self._lock:
            return {sid: {"joined_after_s": self.joined.get(sid), "timeout_s": self.timeouts_s[sid]} for sid in self.ids}


def waiting_line(out: Path, ids: list[str], router: str, timeouts_s: dict[str, float], run: str) -> str:
    """The one line the launcher prints: where the kits are and what it waits for."""
    keys = Keys(run)
    t = max(timeouts_s.values())
    if len(ids) == 1:
        return (f"waiting up to {t:g} s for the external flight software of {ids[0]} to join at {router} "
                f"(liveliness token {keys.alive('agent-' + ids[0])}); its join kit: {out / 'external' / ids[0]}/join.json")
    return (f"waiting up to {t:g} s for the external flight software of {', '.join(ids)} to join at {router} "
            f"(liveliness tokens {keys.base}/alive/agent-<id>); their join kits: {out / 'external'}/<id>/join.json")


def start_external(run_obj: Any, watch: Any, router: str) -> JoinWatch | None:
    """Write the join kits of the run's external spacecraft, print the one line, and watch for
    their tokens (the launcher's part; None when every spacecraft's flight software is built in)."""
    sc = run_obj.sc
    ids = external_ids(sc)
    if not ids:
        return None
    timeouts = {sid: join_timeout_s(sc, sid) for sid in ids}
    jw = JoinWatch(watch, run_obj.run, ids, timeouts)
    # `--join-listen`: the router also listens on an address of another network, and the kits point there
    router = run_obj.opts.get("join_listen") or router
    for sid in ids:
        write_join_kit(run_obj.out, sc, run_obj.run, sid, [router], run_obj.security)
    jw.t0 = time.monotonic()
    print(waiting_line(run_obj.out, ids, router, timeouts, run_obj.run), flush=True)
    return jw
