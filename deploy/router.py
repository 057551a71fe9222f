"""The run's Zenoh router as its own process: `python -m swarmhil.deploy.router --listen EP [--acl-dir DIR] [--tls DIR]`
(what the launcher starts; `swarmhil router` is the same for compose and multi-host deployments).

In a run over several hosts (deploy/mesh.py) a host's router also links to the routers of the hosts
before it: `--connect EP` (repeatable) with `--zid` (its Zenoh id, which the run's ACL names) and
`--credentials` (the `router-<i>` user it authenticates as; with --tls it presents the router
certificate). It prints `router mesh: linked to N routers` once it has a link to every one of them
(`--link-timeout 0`: it waits for them for ever, as a compose deployment's routers do, whose hosts
come up in any order). The `router` role of deploy/proc.py takes the same mesh options.

Lean on purpose (no numpy, no scenario): it must come up fast on a loaded machine. With
`--acl-dir` (a run's secrets directory, bus/acl.py) it authenticates every client and applies the
run's access control. It stops on SIGTERM, and when the launcher that started it is gone
(SWARMHIL_PARENT_PID, besides the launcher's PR_SET_PDEATHSIG). Exit codes: 0 stopped, 2 bad
arguments, 4 the endpoint is taken (the launcher then draws another port), 6 a `--connect` router not
linked within `--link-timeout` seconds.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from swarmhil.bus.acl import read_credential
from swarmhil.deploy.stopping import Stop, stop_on_signals


def router_overrides(listen: str, *, acl_dir: str | None = None, users: str | None = None, acl: str | None = None,
                     tls: str | None = None) -> dict | None:
    """The router's Zenoh settings: authentication and access control from the run's secrets
    directory (`acl_dir`: users.txt + acl.json) or from the two files (`users`, `acl`), and mutual TLS
    from the run's TLS directory (bus/tls.py). ValueError (one line) for a bad combination or directory."""
    overrides: dict = {}
    if acl and not users:
        raise ValueError("--acl needs --users (the ACL names authenticated users)")
    if acl_dir:
        from swarmhil.bus.acl import router_overrides_from_dir  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            overrides.update(router_overrides_from_dir(acl_dir))
        except OSError as exc:
            raise ValueError(f"{acl_dir}: {exc}") from None
    elif users:
        from swarmhil.bus.acl import router_settings  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        overrides.update(router_settings(users, acl) if acl else {"transport/auth/usrpwd/dictionary_file": users})
    if listen.startswith("tls/") != bool(tls):
        raise ValueError(f"--listen {listen} and --tls go together (a tls/ endpoint needs the run's certificates)")
    if tls:
        from swarmhil.bus.tls import router_tls  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        overrides.update(router_tls(tls))
    return overrides or None


LINK_EXIT = 6


def mesh_overrides(zid: str | None, credentials: str | None = None, tls: str | None = None) -> dict:
    """A mesh router's own settings: its Zenoh id, the user/password it authenticates with to the
    routers it connects to (a `user:password` file), and with TLS the router certificate as its
    client certificate (mutual TLS both ways). ValueError (one line) for a bad id or file."""
    ov: dict = {}
    if zid is not None:
        z = zid.lower()
        if not (1 <= len(z) <= 32 and all(c in "0123456789abcdef" for c in z) and not z.startswith("0")):
            raise ValueError(f"--zid {zid}: not a Zenoh id (1 to 32 lowercase hex digits, no leading zero)")
        ov["id"] = z
    if credentials:
        try:
            cred = read_credential(credentials)
        except OSError as exc:
            raise ValueError(f"--credentials {credentials}: {exc.strerror or exc}") from None
        ov.update({"transport/auth/usrpwd/user": cred.user, "transport/auth/usrpwd/password": cred.password})
    if tls:
        from pathlib import Path

        d = Path(tls)
        ov.update({"transport/link/tls/connect_certificate": str(d / "router.pem"),
                   "transport/link/tls/connect_private_key": str(d / "router.key")})
    return ov


def _wait_linked(session: object, want: int, stop: Stop, timeout_s: float) -> int:
    """Wait until the router has a link to `want` other routers (for ever when `timeout_s` <= 0);
    their number (fewer on timeout or stop)."""
    import time

    t_end = time.monotonic() + timeout_s if timeout_s > 0 else float("inf")  # 0: no deadline
    n = 0
    while True:
        n = len(list(session.info.routers_zid()))  # type: ignore[attr-defined]
        if n >= want or time.monotonic() >= t_end or stop.wait(0.02):
            return n


def run_router(listen: str, overrides: dict | None, stop: Stop, also: list[str] = (), connect: list[str] = (),
               link_timeout_s: float = 60.0) -> int:
    import zenoh

    from swarmhil.bus.zenoh_bus import _address_in_use, open_router  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    try:
        session = open_router(listen, overrides, also, connect)
    except zenoh.ZError as exc:
        print(f"error: router: cannot listen on {' and '.join([listen, *also])}: {exc}", file=sys.stderr, flush=True)
        return 4 if _address_in_use(exc) else 2
    except ValueError as exc:
        print(f"error: router: {exc}", file=sys.stderr, flush=True)
        return 2
    print(f"router listening on {' and '.join([listen, *also])}", flush=True)
    if connect:
        n = _wait_linked(session, len(connect), stop, link_timeout_s)
        if n < len(connect) and not stop.is_set():
            print(f"error: router: linked to {n} of the {len(connect)} routers at {', '.join(connect)} within "
                  f"{link_timeout_s:.0f} s", file=sys.stderr, flush=True)
            return LINK_EXIT
        print(f"router mesh: linked to {n} routers", flush=True)
    stop.wait()
    t = threading.Thread(target=session.close, daemon=True)
    t.start()
    t.join(3.0)
    return 0


def add_mesh_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of a mesh router (this module's command line and the `router` role of deploy/proc.py)."""
    ap.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                    help="another host's router of the run to link to (a mesh of routers; repeatable)")
    ap.add_argument("--zid", help="this router's Zenoh id (hex): the run's ACL names the mesh's routers by it")
    ap.add_argument("--credentials", help="file 'user:password' this router authenticates with to the --connect routers")
    ap.add_argument("--link-timeout", type=float, default=60.0, metavar="SECONDS",
                    help="exit (code 6) when a --connect router is not linked within this long (0: wait for ever)")


def with_mesh(args: argparse.Namespace, overrides: dict | None, authenticated: bool) -> dict | None:
    """`overrides` plus the mesh options of `args` (add_mesh_arguments); ValueError (one line) for
    a --connect of another protocol than --listen, or one without --credentials on an
    authenticated router."""
    if not (args.connect or args.zid or args.credentials):
        return overrides
    proto = args.listen.split("/", 1)[0]
    for ep in args.connect:
        if ep.split("/", 1)[0] != proto:
            raise ValueError(f"--connect {ep} is not a {proto}/ endpoint like --listen")
    if args.connect and authenticated and not args.credentials:
        raise ValueError("--connect to routers of an authenticated run needs --credentials (a router-<i> user)")
    return {**(overrides or {}), **mesh_overrides(args.zid, args.credentials, args.tls if args.connect else None)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m swarmhil.deploy.router")
    ap.add_argument("--listen", required=True, help="endpoint to listen on, e.g. tcp/127.0.0.1:7447")
    ap.add_argument("--acl-dir", help="a run's secrets directory (users.txt, acl.json: bus/acl.py)")
    ap.add_argument("--tls", metavar="DIR", help="the run's TLS directory (ca.pem, router.pem/.key): mutual TLS")
    ap.add_argument("--also-listen", action="append", default=[], metavar="ENDPOINT",
                    help="another endpoint to listen on, of the same protocol (external flight software on another host)")
    add_mesh_arguments(ap)
    args = ap.parse_args(argv)
    try:  # a bad directory fails before any signal handler is installed
        overrides = with_mesh(args, router_overrides(args.listen, acl_dir=args.acl_dir, tls=args.tls),
                              authenticated=bool(args.acl_dir))
        for ep in args.also_listen:
            if ep.split("/", 1)[0] != args.listen.split("/", 1)[0]:
                raise ValueError(f"--also-listen {ep} is not a {args.listen.split('/', 1)[0]}/ endpoint like --listen")
    except ValueError as exc:
        print(f"error: router: {exc}", file=sys.stderr, flush=True)
        return 2
    stop = stop_on_signals(signal.SIGTERM, signal.SIGINT)
    return run_router(args.listen, overrides, stop, args.also_listen, args.connect, args.link_timeout)

if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)  # a Zenoh thread must not keep a stopped router alive
