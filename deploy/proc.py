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
from typing import Any

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


def _agent(args: argparse.Namespace, stop: threading.Event, cred: Any, out: Path) -> int:
    """One spacecraft's flight software: its config from the launcher's DIR/scenario.json (no
    pydantic, no launcher, no other mission imported), else validated from a TOML scenario."""
    from deploy.agent_image import agent_config, build_agent, read_agent_config

    cfg = read_agent_config(args.scenario, args.id)
    if cfg is None:
        sc = load_scenario(args.scenario).with_overrides(duration_s=args.duration, seed=args.seed, mode=args.mode,
                                                         speed=args.speed)
        cfg = agent_config(sc, args.id)
    bus = with_faults(ZenohBus(args.router, lease_ms=AGENT_LEASE_MS, credential=cred), f"agent-{args.id}")
    node = build_agent(bus, args.run, cfg)
    stop.wait()
    (out / "agents").mkdir(exist_ok=True)
    (out / "agents" / f"{args.id}.json").write_text(json.dumps(
        {"id": args.id, "pid": os.getpid(), "steps": node.steps, "rejected_packets": node.rejections.total,
         "faults": node.faults}))
    write_import_audit(f"agent-{args.id}")
    _close_within(bus)
    return 0


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
        if role == "companion":
            p.add_argument("--name", required=True)
            p.add_argument("--opts", default="{}")
    r = sub.add_parser("router", help="a Zenoh router session (for compose deployments)")
    r.add_argument("--listen", required=True, help="endpoint to listen on, e.g. tcp/router:7447")
    args = ap.parse_args(argv)
    if args.role == "router":
        from bus.zenoh_bus import open_router

        stop = _stop_event()
        session = open_router(args.listen)
        stop.wait()
        session.close()
        return 0
    logging.basicConfig(level=logging.WARNING, format=f"%(asctime)s {args.role}{'/' + args.id if args.role == 'agent' else ''} %(levelname)s %(message)s")
    stop = _stop_event()
    cred = None
    if args.credentials:
        from bus.acl import read_credential

        cred = read_credential(args.credentials)
    out = Path(args.out)
    if args.role == "agent":  # before any scenario validation: an agent image reads its own config only
        return _agent(args, stop, cred, out)
    sc = load_scenario(args.scenario).with_overrides(duration_s=args.duration, seed=args.seed, mode=args.mode, speed=args.speed)
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
        write_import_audit("plant")
        _close_within(bus)
        return 0
    if args.role == "recorder":
        from bus.recorder import RecorderNode

        bus = ZenohBus(args.router, credential=cred)
        node = RecorderNode(bus, args.run, out / "run.mcap", config=sc.resolved(), document=resolved_document(sc))
        stop.wait()
        stats = node.close()
        (out / "recorder_summary.json").write_text(json.dumps(stats))
        write_import_audit("recorder")
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
        write_import_audit(args.name)
        _close_within(bus)
        return 0
    return 2


def write_import_audit(role: str) -> None:
    """With SWARMHIL_IMPORT_AUDIT=DIR set: write DIR/<role>.json, the top-level packages this process
    has imported and its peak and current RSS, for tests/test_imports.py and bench/agent_rss.py.
    (The peak is /proc VmHWM, not getrusage's ru_maxrss, which keeps the launcher's RSS at the fork.)"""
    where = os.environ.get("SWARMHIL_IMPORT_AUDIT")
    if not where:
        return
    tops = sorted({m.split(".")[0] for m in list(sys.modules)})
    status = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    kb = {k: int(status[k].split()[0]) * 1024 for k in ("VmHWM", "VmRSS")}
    Path(where, f"{role}.json").write_text(json.dumps({"role": role, "modules": tops, "peak_rss_bytes": kb["VmHWM"],
                                                       "rss_bytes": kb["VmRSS"]}))


if __name__ == "__main__":
    code = main()
    # Everything is written and closed by now. Skip the interpreter's teardown: with a Zenoh session
    # and the numba runtime loaded it sometimes outlived the launcher's 10 s SIGTERM grace (7 of 20
    # agents were SIGKILLed at the end of a 24 h camera run), and a Ctrl-C then took over a minute.
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
