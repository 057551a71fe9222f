"""Per-run authentication and access control, with Zenoh's own mechanisms (issue 17).

One run = one router. The launcher makes, in `DIR/secrets/` (mode 0700, files 0600):

- `users.txt`: the router's `transport/auth/usrpwd/dictionary_file` (`user:password` lines);
- `acl.json`: the router's `access_control` block (so a router process reads the directory:
  `swarmhil router --listen EP --acl-dir DIR`);
- `<user>.cred`: one credential per process (`user:password`), passed to the child by path;
- with TLS, `tls/`: the run's CA and certificates (bus/tls.py).

and gives the router an `access_control` block (default deny) that names every process by its
username. A client without a valid user/password cannot open a session at all; an authenticated
one may publish only on its own keys and receive only what it subscribes to:

| user | publishes (put) | liveliness token | subscribes (and receives) |
|---|---|---|---|
| `agent-X` | `sc/X/act`, `sc/X/tm`, `sc/X/tm/**`, `isl/tx/X` | `alive/agent-X` | `sc/X/sense/*`, `isl/rx/X` |
| `plant` | `clock`, `truth`, `sc/*/sense/*`, `event`, `faults` | `alive/plant` | `sc/*/act`, `sync/*`, liveliness `alive/*` |
| `channel` | `isl/rx/*`, `link/stats`, `sync/channel`, `event` | `alive/channel` | `clock`, `truth`, `isl/tx/*`, `sc/*/act`, liveliness `alive/*` |
| `recorder` | `swarmctl/<run>/recorder/ack` | `alive/recorder` | `**` (the whole run), `swarmctl/<run>/recorder/flush` |
| `viz` | nothing | `alive/viz` | `truth`, `sc/*/tm`, `sc/*/tm/image`, `event`, `faults` (marks struck spacecraft), `link/stats`, `isl/rx/*`, `sc/*/sense/*` (landmark returns) |
| `launcher` | `swarmctl/<run>/recorder/flush`, `event` | none | `clock` (the progress bar), `swarmctl/<run>/recorder/ack`, `event` (stalls), `faults` (process faults), liveliness `alive/*` (external flight software joining) |
| other companion | `event`, `sync/<name>` | `alive/<name>` | `**`, liveliness `alive/*` |

(keys under `swarm/<run>/` unless written in full).

Several hosts (deploy/mesh.py): one router per host, the routers linked to each other. Every router
reads the same `users.txt` and `acl.json`, so each applies the run's ACL to its own clients; a
router that connects to another authenticates as `router-<i>` (user/password, and with TLS the
router certificate). A link between two routers carries any key of the run (`swarm/<run>/**`,
`swarmctl/<run>/**`) both ways: what a router forwards was already checked at the edge, by the
router of the process that sent it. Zenoh's user/password authentication names only the side that
opened a link, so the routers are matched by their Zenoh ids (set by the launcher, fresh for each
run) and, with TLS, by the router certificate's common name as well. Zenoh ACL semantics used here (checked against eclipse-zenoh
1.10.2, tests/test_security.py): the router checks `ingress` messages a client sends it (`put`,
`liveliness_token`, `declare_subscriber`, ...) and `egress` messages it forwards to a client; a
message is allowed when a rule's key expression includes the message's key; a denied put is dropped
silently (the publisher sees no error). A process that publishes is also told (egress
`declare_subscriber` on the whole run) which subscribers exist: a declared publisher drops puts
that match no subscriber it knows of, and the subscribers' wildcards (`sc/*/act`, `**`) are not
included in its own keys. Usernames are the identity: zids are chosen by clients. An open router
refuses clients that present credentials, and a secured one clients that present none.
"""
from __future__ import annotations

import json
import os
import secrets
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable

from swarmhil.bus.keys import Keys, check_token
from swarmhil.bus.tls import client_tls, make_run_tls

SUB_INGRESS = ["declare_subscriber"]
# what one router forwards to another (a mesh of routers, deploy/mesh.py)
MESH_MESSAGES = ["put", "delete", "declare_subscriber", "declare_queryable", "query", "reply", "liveliness_token",
                 "declare_liveliness_subscriber", "liveliness_query"]
ROUTER_USER_PREFIX = "router-"  # router-<i>: the user a router on host i > 0 connects to the others as
ROUTER_CN = "router"            # the common name of the run's router certificate (bus/tls.py)
LIVE_SUB_INGRESS = ["declare_liveliness_subscriber", "liveliness_query"]


@dataclass(frozen=True)
class Credential:
    """A process's identity on the run's router: user/password, and with TLS (bus/tls.py) its
    certificate settings (`transport/link/tls/...`)."""

    user: str
    password: str
    tls: dict[str, Any] = field(default_factory=dict, compare=False)

    def zenoh_overrides(self) -> dict[str, Any]:
        return {"transport/auth/usrpwd/user": self.user, "transport/auth/usrpwd/password": self.password, **self.tls}

    def with_tls(self, tls_dir: str | Path) -> "Credential":
        return replace(self, tls=client_tls(tls_dir, self.user))


def read_credential(path: str | Path) -> Credential:
    text = Path(path).read_text().strip()
    user, sep, password = text.partition(":")
    if not sep or not user or not password:
        raise ValueError(f"{path}: not a 'user:password' credential file")
    return Credential(user, password)


def _write_private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.chmod(path, 0o600)


@dataclass
class Grants:
    put: list[str]
    token: list[str]
    sub: list[str]
    live_sub: list[str]


def grants(keys: Keys, user: str) -> Grants:
    """What one process may publish and subscribe to (see the table above)."""
    b = keys.base
    if user.startswith("agent-"):
        sid = check_token(user[len("agent-"):])
        return Grants(put=[keys.act(sid), keys.tm(sid), f"{keys.tm(sid)}/**", keys.isl_tx(sid)],
                      token=[keys.alive(user)], sub=[f"{b}/sc/{sid}/sense/*", keys.isl_rx(sid)], live_sub=[])
    if user == "plant":
        return Grants(put=[keys.clock, keys.truth, f"{b}/sc/*/sense/*", keys.event, keys.faults], token=[keys.alive("plant")],
                      sub=[keys.act_all, keys.sync_all], live_sub=[keys.alive_all])
    if user == "channel":
        return Grants(put=[f"{b}/isl/rx/*", keys.link_stats, keys.sync("channel"), keys.event],
                      token=[keys.alive("channel")],
                      sub=[keys.clock, keys.truth, keys.isl_tx_all, keys.act_all], live_sub=[keys.alive_all])
    # the recorder's flush handshake with the launcher (bus/recorder.py), outside swarm/<run>/**
    flush, ack = keys.recorder_flush, keys.recorder_ack
    if user == "recorder":
        return Grants(put=[ack], token=[keys.alive("recorder")], sub=[keys.all, flush], live_sub=[])
    if user == "viz":
        return Grants(put=[], token=[keys.alive("viz")],
                      sub=[keys.truth, keys.tm_all, f"{b}/sc/*/tm/image", keys.event, keys.faults, keys.link_stats,
                           f"{b}/isl/rx/*", f"{b}/sc/*/sense/*"],
                      live_sub=[])
    if user == "launcher":  # events: agent_restart, recorder_restart (its supervision)
        # liveliness: it waits for external flight software to join (deploy/external.py)
        return Grants(put=[flush, keys.event], token=[], sub=[keys.clock, ack, keys.event, keys.faults],
                      live_sub=[keys.alive_all])
    # any other companion (one a plugin registers in deploy/companions.py): it may read the whole
    # run, and publish only events and its own lockstep barrier
    name = check_token(user, "process name")
    return Grants(put=[keys.event, keys.sync(name)], token=[keys.alive(name)], sub=[keys.all], live_sub=[keys.alive_all])


def is_router_user(user: str) -> bool:
    return user.startswith(ROUTER_USER_PREFIX)


def acl_config(run: str, users: Iterable[str], router_zids: Iterable[str] = (), tls: bool = False) -> dict[str, Any]:
    """The router's `access_control` block: default deny, one subject and policy per user; with
    `router_zids` (a mesh of routers), one more subject, the routers by Zenoh id (and, with `tls`,
    by the router certificate's common name too), allowed every message on the run's keys both
    ways. `router-<i>` users only authenticate a router's link: they get no policy of their own."""
    keys = Keys(run)
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def rule(uid: str, what: str, flow: str, messages: list[str], key_exprs: list[str]) -> str | None:
        if not key_exprs:
            return None
        rid = f"{uid}:{what}"
        rules.append({"id": rid, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": key_exprs})
        return rid

    for user in users:
        if is_router_user(user):
            continue
        g = grants(keys, user)
        ids = [rule(user, "put", "ingress", ["put"], g.put),
               # a declared publisher learns of matching subscribers through the router and drops puts
               # that have none (write-side filtering): it must be told about them, and they are
               # declared with wildcards (`sc/*/act`, `**`) that the publisher's own keys do not include
               rule(user, "put-match", "egress", ["declare_subscriber"],
                    [keys.all, keys.control_all] if g.put else []),
               rule(user, "token", "ingress", ["liveliness_token"], g.token),
               rule(user, "sub", "ingress", SUB_INGRESS, g.sub),
               rule(user, "recv", "egress", ["put"], g.sub),
               rule(user, "live-sub", "ingress", LIVE_SUB_INGRESS, g.live_sub),
               rule(user, "live-recv", "egress", ["liveliness_token"], g.live_sub)]
        subjects.append({"id": user, "usernames": [user]})
        policies.append({"id": user, "rules": [r for r in ids if r], "subjects": [user]})
    zids = sorted(router_zids)
    if zids:
        rules.append({"id": "mesh", "permission": "allow", "flows": ["ingress", "egress"], "messages": MESH_MESSAGES,
                      "key_exprs": [keys.all, keys.control_all]})
        subjects.append({"id": "mesh-routers", "zids": zids, **({"cert_common_names": [ROUTER_CN]} if tls else {})})
        policies.append({"id": "mesh-routers", "rules": ["mesh"], "subjects": ["mesh-routers"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


@dataclass
class RunSecurity:
    """The files and router settings of one authenticated run."""

    dir: Path
    dictionary: Path
    acl: dict[str, Any]
    credentials: dict[str, Path]
    tls: Any = None  # bus.tls.RunTls when the run's links are TLS

    def router_overrides(self) -> dict[str, Any]:
        ov = {"transport/auth/usrpwd/dictionary_file": str(self.dictionary), "access_control": self.acl}
        return {**ov, **(self.tls.router_overrides() if self.tls else {})}

    def credential(self, user: str) -> Credential:
        cred = read_credential(self.credentials[user])
        return cred.with_tls(self.tls.dir) if self.tls else cred


ACL_FILE = "acl.json"     # the router's access_control block, beside users.txt (`swarmhil router --acl-dir`)
USERS_FILE = "users.txt"


def router_overrides_from_dir(d: str | Path) -> dict[str, Any]:
    """The router settings of a run's secrets directory (what `make_run_security` wrote there):
    `users.txt` as the usrpwd dictionary and `acl.json` as the access_control block."""
    d = Path(d)
    if not (d / USERS_FILE).is_file() or not (d / ACL_FILE).is_file():
        raise ValueError(f"{d}: not a run's secrets directory (needs {USERS_FILE} and {ACL_FILE})")
    return {"transport/auth/usrpwd/dictionary_file": str((d / USERS_FILE).resolve()),
            "access_control": json.loads((d / ACL_FILE).read_text())}


def router_settings(dictionary: str | Path, acl_file: str | Path) -> dict[str, Any]:
    """A router's auth and ACL settings from the two files `make_run_security` wrote (a router started
    on its own with --users/--acl: compose, another host)."""
    return {"transport/auth/usrpwd/dictionary_file": str(dictionary), "access_control": json.loads(Path(acl_file).read_text())}


def make_run_security(out: Path, run: str, users: Iterable[str], *, tls: bool = False,
                      tls_hosts: Iterable[str] = (), router_zids: Iterable[str] = ()) -> RunSecurity:
    """Fresh random passwords for every process of this run, written readable by the user only;
    also `acl.json` (the router's access control) and, with tls, the run's certificates
    (bus/tls.py; tls_hosts: the router's addresses on other hosts). `router_zids`: the Zenoh ids
    of the run's routers when there are several (a mesh; `router-<i>` users authenticate them)."""
    users = list(users)
    d = out / "secrets"
    d.mkdir(mode=0o700, exist_ok=True)
    os.chmod(d, 0o700)
    creds = {u: Credential(check_token(u, "process name"), secrets.token_urlsafe(24)) for u in users}
    dictionary = d / USERS_FILE
    _write_private(dictionary, "".join(f"{c.user}:{c.password}\n" for c in creds.values()))
    acl = acl_config(run, users, router_zids, tls)
    _write_private(d / ACL_FILE, json.dumps(acl, indent=1))
    paths = {}
    for u, c in creds.items():
        paths[u] = d / f"{u}.cred"
        _write_private(paths[u], f"{c.user}:{c.password}\n")
    run_tls = None
    if tls:  # (a router's links to other routers present the router certificate)
        run_tls = make_run_tls(d, [u for u in users if not is_router_user(u)], tls_hosts)
    return RunSecurity(d, dictionary, acl, paths, run_tls)
