"""The bus floor: N worker processes exchanging empty ticks and replies with a coordinator over a
Python Zenoh router, in lockstep, for a given number of steps (no physics, no flight software).

    python bench/bus_floor.py --workers 20 --steps 8640
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bus.zenoh_bus import endpoint, free_loopback_port, open_client, open_router  # noqa: E402


def worker(router: str, i: int) -> None:
    s = open_client(router)
    pub = s.declare_publisher(f"floor/rep/{i}")
    reply = bytes(200)
    s.declare_subscriber("floor/tick", lambda sample: pub.put(reply))
    s.liveliness().declare_token(f"floor/alive/{i}")
    threading.Event().wait()


def coordinator(workers: int, steps: int) -> float:
    router_ep = endpoint(free_loopback_port())
    router = open_router(router_ep)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    procs = [subprocess.Popen([sys.executable, __file__, "--worker", str(i), "--router", router_ep], env=env)
             for i in range(workers)]
    s = open_client(router_ep)
    cv = threading.Condition()
    state = {"step": -1, "n": 0, "alive": 0}

    def on_rep(_sample) -> None:
        with cv:
            state["n"] += 1
            cv.notify()

    def on_alive(_sample) -> None:
        with cv:
            state["alive"] += 1
            cv.notify()

    s.declare_subscriber("floor/rep/*", on_rep)
    s.liveliness().declare_subscriber("floor/alive/*", on_alive, history=True)
    with cv:
        cv.wait_for(lambda: state["alive"] >= workers, timeout=120)
    pub = s.declare_publisher("floor/tick")
    tick = bytes(64)
    t0 = time.perf_counter()
    for k in range(steps):
        with cv:
            state["n"] = 0
        pub.put(tick)
        with cv:
            cv.wait_for(lambda: state["n"] >= workers, timeout=10)
    wall = time.perf_counter() - t0
    for p in procs:
        p.kill()  # our own children, by PID
        p.wait()
    s.close()
    router.close()
    return wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=20)
    ap.add_argument("--steps", type=int, default=8640)
    ap.add_argument("--worker", type=int)
    ap.add_argument("--router")
    a = ap.parse_args()
    if a.worker is not None:
        worker(a.router, a.worker)
        return
    wall = coordinator(a.workers, a.steps)
    print(f"bus floor: {a.workers} workers, {a.steps} steps, {wall:.2f} s, {wall / a.steps * 1e3:.3f} ms/step")


if __name__ == "__main__":
    main()
