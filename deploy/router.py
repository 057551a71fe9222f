"""The run's Zenoh router as its own process: `python -m deploy.router --listen EP [--acl-dir DIR]`
(what the launcher starts; `swarmhil router` is the same for compose and multi-host deployments).

Lean on purpose (no numpy, no scenario): it must come up fast on a loaded machine. With
`--acl-dir` (a run's secrets directory, bus/acl.py) it authenticates every client and applies the
run's access control. It stops on SIGTERM, and when the launcher that started it is gone
(SWARMHIL_PARENT_PID, besides the launcher's PR_SET_PDEATHSIG). Exit codes: 0 stopped, 2 bad
arguments, 4 the endpoint is taken (the launcher then draws another port).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading


def _overrides(acl_dir: str | None) -> dict | None:
    """The run's authentication and access control from its secrets directory (ValueError if not one)."""
    if not acl_dir:
        return None
    from bus.acl import router_overrides_from_dir

    try:
        return router_overrides_from_dir(acl_dir)
    except OSError as exc:
        raise ValueError(f"{acl_dir}: {exc}") from None


def run_router(listen: str, acl_dir: str | None, stop: threading.Event) -> int:
    import zenoh

    from bus.zenoh_bus import _address_in_use, open_router

    try:
        overrides = _overrides(acl_dir)
    except ValueError as exc:
        print(f"error: router: {exc}", file=sys.stderr, flush=True)
        return 2
    try:
        session = open_router(listen, overrides)
    except zenoh.ZError as exc:
        print(f"error: router: cannot listen on {listen}: {exc}", file=sys.stderr, flush=True)
        return 4 if _address_in_use(exc) else 2
    except ValueError as exc:
        print(f"error: router: {exc}", file=sys.stderr, flush=True)
        return 2
    print(f"router listening on {listen}", flush=True)
    stop.wait()
    t = threading.Thread(target=session.close, daemon=True)
    t.start()
    t.join(3.0)
    return 0


def _watch_parent(stop: threading.Event) -> None:
    parent = int(os.environ.get("SWARMHIL_PARENT_PID", "0") or 0)
    if not parent:
        return

    def watch() -> None:
        while not stop.wait(0.5):
            if os.getppid() != parent:
                stop.set()
    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m deploy.router")
    ap.add_argument("--listen", required=True, help="endpoint to listen on, e.g. tcp/127.0.0.1:7447")
    ap.add_argument("--acl-dir", help="a run's secrets directory (users.txt, acl.json: bus/acl.py)")
    args = ap.parse_args(argv)
    try:
        _overrides(args.acl_dir)  # a bad directory fails before any signal handler is installed
    except ValueError as exc:
        print(f"error: router: {exc}", file=sys.stderr, flush=True)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    _watch_parent(stop)
    return run_router(args.listen, args.acl_dir, stop)


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)  # a Zenoh thread must not keep a stopped router alive
