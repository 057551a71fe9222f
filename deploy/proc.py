"""Entry points of the run's child processes: `python -m deploy.proc ROLE ...`.

Each is a flight-software image or a ground process with its own Zenoh session; the launcher
(deploy/launcher.py) starts them and ends them by PID. Children ignore SIGINT: on Ctrl-C the
launcher stops them in order (plant, agents, recorder) so the recording is finished cleanly.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
from pathlib import Path

from bus.faults import wrap as with_faults
from bus.zenoh_bus import ZenohBus
from deploy.scenario import load_scenario, resolved_document


# An agent's Zenoh lease: a frozen (SIGSTOPped) agent's liveliness token goes after this long.
# 2 s was too short on a loaded 2-core machine: an agent that was merely starved of CPU for 2 s
# lost its token and was declared dead (issue 10: a false death under load). 5 s keeps detection
# quick; a lockstep miss is caught sooner anyway by the plant's deadline.
AGENT_LEASE_MS = 5000


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--router", required=True, help="zenoh endpoint of the run's router, e.g. tcp/127.0.0.1:7447")
    p.add_argument("--run", required=True)
    p.add_argument("--scenario", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--duration", type=float)
    p.add_argument("--seed", type=int)
    p.add_argument("--mode")
    p.add_argument("--speed", type=float)
    p.add_argument("--credentials", help="file 'user:password' authenticating this process to the run's router (bus/acl.py)")
    p.add_argument("--tls", metavar="DIR", help="the run's TLS directory (ca.pem, <user>.pem/.key; bus/tls.py): "
                   "mutual TLS to a router on a tls/... endpoint; needs --credentials (the user names the certificate)")


def _stop_event() -> threading.Event:
    stop = threading.Event()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    _watch_parent(stop)
    return stop


def _watch_parent(stop: threading.Event) -> None:
    """No orphans: stop when the launcher is gone. The launcher already asks the kernel for a
    SIGTERM on its death (PR_SET_PDEATHSIG); this watchdog covers a platform without it."""
    parent = int(os.environ.get("SWARMHIL_PARENT_PID", "0") or 0)
    if not parent:
        return

    def watch() -> None:
        while not stop.wait(0.5):
            if os.getppid() != parent:
                logging.getLogger("swarmhil.proc").warning("launcher (pid %d) is gone; stopping", parent)
                stop.set()
    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _close_within(bus: ZenohBus, timeout_s: float = 3.0) -> None:
    """Close the session, but never let a hung close (STACK-NOTES) keep the process alive."""
    t = threading.Thread(target=bus.close, daemon=True)
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        logging.getLogger("swarmhil.proc").warning("zenoh session close took over %.0f s; exiting anyway", timeout_s)
        sys.stdout.flush()
        os._exit(0)


def _await_run_end(node: object, timeout_s: float) -> None:
    import time

    t_end = time.monotonic() + timeout_s
    while not getattr(node, "run_end", True) and time.monotonic() < t_end:
        time.sleep(0.05)


def _router(args: argparse.Namespace) -> int:
    """The run's router on its own: auth dictionary + ACL (bus/acl.py) and mutual TLS (bus/tls.py)."""
    from bus.zenoh_bus import open_router

    overrides: dict = {}
    if args.acl and not args.users:
        print("router: --acl needs --users (the ACL names authenticated users)", file=sys.stderr)
        return 2
    if args.users:
        from bus.acl import router_settings

        overrides.update(router_settings(args.users, args.acl) if args.acl else
                         {"transport/auth/usrpwd/dictionary_file": args.users})
    if args.tls:
        from bus.tls import router_tls

        overrides.update(router_tls(args.tls))
    if args.listen.startswith("tls/") != bool(args.tls):
        print(f"router: --listen {args.listen} and --tls go together (a tls/ endpoint needs the run's certificates)",
              file=sys.stderr)
        return 2
    stop = _stop_event()
    session = open_router(args.listen, overrides)
    stop.wait()
    session.close()
    return 0


def _probe(router: str, timeout_s: float) -> int:
    """TCP connect to the host:port of a zenoh endpoint (`tcp/`, `tls/`): the router's health check."""
    import socket

    try:
        host, _, port = router.split("/", 1)[1].rpartition(":")
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
            return 0
    except (OSError, ValueError, IndexError) as exc:
        print(f"probe: {router}: {exc}", file=sys.stderr)
        return 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m deploy.proc")
    sub = ap.add_subparsers(dest="role", required=True)
    for role in ("plant", "agent", "recorder", "companion"):
        p = sub.add_parser(role)
        _common(p)
        if role == "agent":
            p.add_argument("--id", required=True)
        if role == "plant":
            p.add_argument("--companions", default="")
            p.add_argument("--barriers", default="")
        if role == "recorder":
            # without the launcher's flush handshake (compose, several hosts): a recorder told to stop
            # still waits up to this long for the plant's run_end (the plant publishes its last truth,
            # then run_end, on one session), so everything the plant published is recorded
            p.add_argument("--await-run-end", type=float, default=0.0, metavar="SECONDS")
        if role == "companion":
            p.add_argument("--name", required=True)
            p.add_argument("--opts", default="{}")
    r = sub.add_parser("router", help="a Zenoh router session (compose deployments, another host)")
    r.add_argument("--listen", required=True, help="endpoint to listen on, e.g. tls/router:7447")
    r.add_argument("--users", help="the run's user/password dictionary (secrets/users.txt, bus/acl.py)")
    r.add_argument("--acl", help="the run's access control (secrets/acl.json); needs --users")
    r.add_argument("--tls", metavar="DIR", help="the run's TLS directory (ca.pem, router.pem/.key): mutual TLS")
    h = sub.add_parser("probe", help="exit 0 when something accepts TCP connections at a router endpoint "
                       "(a compose health check)")
    h.add_argument("--router", required=True)
    h.add_argument("--timeout", type=float, default=2.0)
    args = ap.parse_args(argv)
    if args.role == "router":
        return _router(args)
    if args.role == "probe":
        return _probe(args.router, args.timeout)
    logging.basicConfig(level=logging.WARNING, format=f"%(asctime)s {args.role}{'/' + args.id if args.role == 'agent' else ''} %(levelname)s %(message)s")
    stop = _stop_event()
    cred = None
    if args.credentials:
        from bus.acl import read_credential

        cred = read_credential(args.credentials)
        if args.tls:
            cred = cred.with_tls(args.tls)
    elif args.tls:
        ap.error("--tls needs --credentials (the user names the certificate)")
    sc = load_scenario(args.scenario).with_overrides(duration_s=args.duration, seed=args.seed, mode=args.mode, speed=args.speed)
    out = Path(args.out)
    if args.role == "plant":
        from plant.node import PlantNode

        bus = with_faults(ZenohBus(args.router, credential=cred), "plant")
        comps = tuple(c for c in args.companions.split(",") if c)
        node = PlantNode(bus, args.run, sc, expect_processes=("recorder", *comps),
                         barriers=tuple(b for b in args.barriers.split(",") if b))
        try:
            node.wait_ready(should_stop=stop.is_set)
        except TimeoutError as exc:  # the launcher sees exit code 3 and says why
            logging.getLogger("swarmhil.proc").error("plant: %s", exc)
            (out / "plant_error.txt").write_text(f"{exc}\n")
            _close_within(bus)
            os._exit(3)  # a Zenoh session thread must not keep a failed plant alive
        summary = node.run(should_stop=stop.is_set)
        (out / "plant_summary.json").write_text(json.dumps(summary, indent=1))
        _close_within(bus)
        return 0
    if args.role == "agent":
        from deploy.launcher import make_agent

        bus = with_faults(ZenohBus(args.router, lease_ms=AGENT_LEASE_MS, credential=cred), f"agent-{args.id}")
        node = make_agent(bus, args.run, sc, args.id)
        stop.wait()
        (out / "agents").mkdir(exist_ok=True)
        (out / "agents" / f"{args.id}.json").write_text(json.dumps(
            {"id": args.id, "pid": os.getpid(), "steps": node.steps, "rejected_packets": node.rejections.total,
             "faults": node.faults}))
        _close_within(bus)
        return 0
    if args.role == "recorder":
        from bus.recorder import RecorderNode

        bus = ZenohBus(args.router, credential=cred)
        node = RecorderNode(bus, args.run, out / "run.mcap", config=sc.resolved(), document=resolved_document(sc))
        stop.wait()
        _await_run_end(node, args.await_run_end)
        stats = node.close()
        (out / "recorder_summary.json").write_text(json.dumps(stats))
        _close_within(bus)
        return 0
    if args.role == "companion":
        from deploy.companions import load

        comp = load(args.name)
        bus = with_faults(ZenohBus(args.router, credential=cred), args.name)
        obj = comp.module.start(bus, args.run, sc, out, json.loads(args.opts))
        stop.wait()
        stats = obj.close()
        (out / f"{args.name}_summary.json").write_text(json.dumps(stats or {}, indent=1))
        _close_within(bus)
        return 0
    return 2


if __name__ == "__main__":
    code = main()
    # Everything is written and closed by now. Skip the interpreter's teardown: with a Zenoh session
    # and the numba runtime loaded it sometimes outlived the launcher's 10 s SIGTERM grace (7 of 20
    # agents were SIGKILLed at the end of a 24 h camera run), and a Ctrl-C then took over a minute.
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
