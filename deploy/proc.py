"""Entry points of the run's child processes: `python -m swarmhil.deploy.proc ROLE ...`.

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
import time
from pathlib import Path
from typing import Any

from swarmhil.bus.discovery import room_parts_loaded
from swarmhil.bus.faults import faults_for
from swarmhil.bus.faults import wrap as with_faults
from swarmhil.bus.zenoh_bus import ZenohBus
from swarmhil.deploy.scenario import load_scenario, plant_config, resolved_document
from swarmhil.deploy.stopping import Stop, stop_on_signals

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


def _stop_event() -> Stop:
    """SIGTERM stops (deploy/stopping.py); Ctrl-C is the launcher's to handle."""
    return stop_on_signals(signal.SIGTERM, ignore=(signal.SIGINT,))


# A child whose session has had no router this long exits (the router is gone: no orphans). Longer
# than a client's reconnection after a pause (SIGSTOP, then SIGCONT) so a resumed agent rejoins.
ROUTER_GRACE_S = 8.0
ROUTER_LOST_EXIT = 5  # exit code of a child that stopped because it lost the router (a failure: restartable)
_router_lost = threading.Event()
# Real-time runs: the recorder lowers its priority by this much (SWARMHIL_RECORDER_NICE; 0 keeps it).
_nice = os.environ.get("SWARMHIL_RECORDER_NICE", "10")
RECORDER_NICE_REALTIME = int(_nice) if _nice.strip().lstrip("-").isdigit() else 10


def _watch_router(bus: Any, stop: Stop, grace_s: float = ROUTER_GRACE_S) -> None:
    """Stop when the session has been without its router for `grace_s` (the router process was
    killed, or the launcher and the router with it): every child then ends as on SIGTERM."""
    log = logging.getLogger("swarmhil.proc")
    session = getattr(bus, "session", None) or getattr(getattr(bus, "inner", None), "session")

    def watch() -> None:
        lost_since = None
        while not stop.wait(0.25):
            try:
                connected = bool(list(session.info.routers_zid()))
            except Exception:  # a closed session
                return
            if connected:
                if lost_since is not None:
                    log.warning("router is back after %.1f s", time.monotonic() - lost_since)
                lost_since = None
            elif lost_since is None:
                lost_since = time.monotonic()
                log.warning("lost the router; waiting %.0f s for it", grace_s)
            elif time.monotonic() - lost_since > grace_s:
                log.error("no router for %.0f s: stopping", grace_s)
                _router_lost.set()
                stop.set()
                return
    threading.Thread(target=watch, name="router-watchdog", daemon=True).start()


def _close_within(bus: ZenohBus, timeout_s: float = 3.0) -> None:
    """Close the session, but never let a hung close (STACK-NOTES) keep the process alive."""
    t = threading.Thread(target=bus.close, daemon=True)
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        logging.getLogger("swarmhil.proc").warning("zenoh session close took over %.0f s; exiting anyway", timeout_s)
        sys.stdout.flush()
        os._exit(0)


def _agent(args: argparse.Namespace, stop: Stop, cred: Any, out: Path) -> int:
    """One spacecraft's flight software: its config from the launcher's DIR/scenario.json (no
    pydantic, no launcher, no other mission imported), else validated from a TOML scenario."""
    from swarmhil.deploy.agent_image import agent_config, build_agent, read_agent_config  # this process role's modules only (tests/test_imports.py)

    cfg = read_agent_config(args.scenario, args.id)
    if cfg is None:
        sc = load_scenario(args.scenario).with_overrides(duration_s=args.duration, seed=args.seed, mode=args.mode,
                                                         speed=args.speed)
        cfg = agent_config(sc, args.id)
    name = f"agent-{args.id}"
    # The flight software runs on the dispatcher thread, never on Zenoh's network thread: a step can
    # take seconds (paper 000's cold fit on a loaded machine: 12 s), and with the step on the network
    # thread the agent's session was dropped by the router mid-step (issue 24).
    bus = with_faults(ZenohBus(args.router, lease_ms=AGENT_LEASE_MS, credential=cred, direct=False), name)
    _watch_router(bus, stop)
    node = build_agent(bus, args.run, cfg)
    stop.wait()
    (out / "agents").mkdir(exist_ok=True)
    (out / "agents" / f"{args.id}.json").write_text(json.dumps(
        {"id": args.id, "pid": os.getpid(), "steps": node.steps, "rejected_packets": node.rejections.total,
         "faults": node.faults}))
    write_import_audit(f"agent-{args.id}")
    _close_within(bus)
    return 0


def _await_run_end(node: object, timeout_s: float) -> None:
    import time

    t_end = time.monotonic() + timeout_s
    while not getattr(node, "run_end", True) and time.monotonic() < t_end:
        time.sleep(0.05)


def _router(args: argparse.Namespace) -> int:
    """The run's router on its own (compose, another host): deploy/router.py with the run's auth
    dictionary + ACL (bus/acl.py: --acl-dir, or --users/--acl), mutual TLS (bus/tls.py: --tls) and,
    on one of several hosts, its links to the other hosts' routers (--connect, --zid, --credentials)."""
    from swarmhil.deploy.router import router_overrides, run_router, with_mesh  # this process role's modules only (tests/test_imports.py)

    try:
        overrides = with_mesh(args, router_overrides(args.listen, acl_dir=args.acl_dir, users=args.users, acl=args.acl,
                                                     tls=args.tls), authenticated=bool(args.acl_dir or args.users))
    except ValueError as exc:
        print(f"error: router: {exc}", file=sys.stderr, flush=True)
        return 2
    return run_router(args.listen, overrides, _stop_event(), connect=args.connect, link_timeout_s=args.link_timeout)


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
    ap = argparse.ArgumentParser(prog="python -m swarmhil.deploy.proc")
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
            p.add_argument("--segment", type=int, default=0, help="0: run.mcap; N: run.NNN.mcap (a restart)")
            # without the launcher's flush handshake (compose, several hosts): a recorder told to stop
            # still waits up to this long for the plant's run_end (the plant publishes its last truth,
            # then run_end, on one session), so everything the plant published is recorded
            p.add_argument("--await-run-end", type=float, default=0.0, metavar="SECONDS")
        if role == "companion":
            p.add_argument("--name", required=True)
            p.add_argument("--opts", default="{}")
    r = sub.add_parser("router", help="the run's Zenoh router (launcher, compose deployments, another host)")
    r.add_argument("--listen", required=True, help="endpoint to listen on, e.g. tcp/127.0.0.1:7447 or tls/router:7447")
    r.add_argument("--acl-dir", help="the run's secrets directory (users.txt, acl.json: bus/acl.py)")
    r.add_argument("--users", help="the run's user/password dictionary (secrets/users.txt, bus/acl.py)")
    r.add_argument("--acl", help="the run's access control (secrets/acl.json); needs --users")
    r.add_argument("--tls", metavar="DIR", help="the run's TLS directory (ca.pem, router.pem/.key): mutual TLS")
    from swarmhil.deploy.router import add_mesh_arguments  # its options only (tests/test_imports.py)

    add_mesh_arguments(r)  # a host's router of a run over several hosts (deploy/mesh.py, a compose project per host)
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
        from swarmhil.bus.acl import read_credential  # this process role's modules only (tests/test_imports.py)

        cred = read_credential(args.credentials)
        if args.tls:
            cred = cred.with_tls(args.tls)
    elif args.tls:
        ap.error("--tls needs --credentials (the user names the certificate)")
    out = Path(args.out)
    if args.role == "agent":  # before any scenario validation: an agent image reads its own config only
        return _agent(args, stop, cred, out)
    # a ground process: the launcher validated the flight software's part; none is imported here
    sc = load_scenario(args.scenario, flight_software=False).with_overrides(
        duration_s=args.duration, seed=args.seed, mode=args.mode, speed=args.speed)
    if args.role == "plant":
        from swarmhil.plant.node import PlantNode  # this process role's modules only (tests/test_imports.py)

        bus = with_faults(ZenohBus(args.router, credential=cred, direct=faults_for("plant") is None), "plant")
        _watch_router(bus, stop)
        comps = tuple(c for c in args.companions.split(",") if c)
        node = PlantNode(bus, args.run, plant_config(sc), expect_processes=("recorder", *comps),
                         barriers=tuple(b for b in args.barriers.split(",") if b))
        from swarmhil.deploy.external import plant_ready_timeout_s  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            node.wait_ready(timeout_s=plant_ready_timeout_s(sc), should_stop=stop.is_set)
        except TimeoutError as exc:  # the launcher sees exit code 3 and says why
            logging.getLogger("swarmhil.proc").error("plant: %s", exc)
            (out / "plant_error.txt").write_text(f"{exc}\n")
            _close_within(bus)
            os._exit(3)  # a Zenoh session thread must not keep a failed plant alive
        summary = node.run(should_stop=stop.is_set)
        (out / "plant_summary.json").write_text(json.dumps(summary, indent=1))
        write_import_audit("plant")
        _close_within(bus)
        return 0
    if args.role == "recorder":
        from swarmhil.bus.recorder import RecorderNode  # this process role's modules only (tests/test_imports.py)

        if sc.mode == "realtime" and RECORDER_NICE_REALTIME:
            # off the step's critical path: it only has to keep up on average (Zenoh buffers), while
            # a plant or agent scheduled late misses the wall deadline (docs/benchmarks.md, soak)
            os.nice(RECORDER_NICE_REALTIME)
        bus = ZenohBus(args.router, credential=cred)
        _watch_router(bus, stop)
        from swarmhil.bus.mcap_tools import segment_name  # this process role's modules only (tests/test_imports.py)

        node = RecorderNode(bus, args.run, out / segment_name(args.segment), config=sc.resolved(),
                            document=resolved_document(sc), segment=args.segment)
        stop.wait()
        _await_run_end(node, args.await_run_end)
        stats = node.close()
        (out / "recorder_summary.json").write_text(json.dumps(stats))
        write_import_audit("recorder")
        _close_within(bus)
        return 0
    if args.role == "companion":
        from swarmhil.deploy.companions import load  # this process role's modules only (tests/test_imports.py)

        comp = load(args.name)
        bus = with_faults(ZenohBus(args.router, credential=cred), args.name)
        _watch_router(bus, stop)
        obj = comp.module.start(bus, args.run, sc, out, json.loads(args.opts))
        stop.wait()
        stats = obj.close()
        (out / f"{args.name}_summary.json").write_text(json.dumps(stats or {}, indent=1))
        write_import_audit(args.name)
        _close_within(bus)
        return 0
    return 2


def write_import_audit(role: str) -> None:
    """With SWARMHIL_IMPORT_AUDIT=DIR set: write DIR/<role>.json, the top-level packages this process
    has imported, its peak and current RSS, and its PSS and USS at exit (/proc smaps_rollup), for
    tests/test_imports.py, tests/test_agents100.py and bench/agent_rss.py.
    (The peak is /proc VmHWM, not getrusage's ru_maxrss, which keeps the launcher's RSS at the fork.)"""
    where = os.environ.get("SWARMHIL_IMPORT_AUDIT")
    if not where:
        return
    loaded = list(sys.modules)
    tops = sorted({m.split(".")[0] for m in loaded})
    status = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    kb = {k: int(status[k].split()[0]) * 1024 for k in ("VmHWM", "VmRSS", "RssAnon", "RssFile")}
    roll = dict(line.split(":", 1) for line in Path("/proc/self/smaps_rollup").read_text().splitlines()[1:] if ":" in line)
    sm = {k: int(roll[k].split()[0]) * 1024 for k in ("Pss", "Private_Clean", "Private_Dirty")}
    Path(where, f"{role}.json").write_text(json.dumps({
        "role": role, "modules": tops, "room_parts": room_parts_loaded(loaded), "peak_rss_bytes": kb["VmHWM"], "rss_bytes": kb["VmRSS"],
        "rss_anon_bytes": kb["RssAnon"], "rss_file_bytes": kb["RssFile"],
        # what N such processes add up to: shared library pages split among their sharers (PSS), and
        # this process's own pages (USS); RSS counts every mapped page of shared files in full, and how
        # many the kernel maps depends on the page cache (docs/performance.md "RSS, PSS and USS")
        "pss_bytes": sm["Pss"], "uss_bytes": sm["Private_Clean"] + sm["Private_Dirty"]}))

if __name__ == "__main__":
    code = main()
    if code == 0 and _router_lost.is_set():
        code = ROUTER_LOST_EXIT
    # Everything is written and closed by now. Skip the interpreter's teardown: with a Zenoh session
    # and the numba runtime loaded it sometimes outlived the launcher's 10 s SIGTERM grace (7 of 20
    # agents were SIGKILLed at the end of a 24 h camera run), and a Ctrl-C then took over a minute.
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
