"""The bus floor: N worker processes exchanging empty ticks and replies with a coordinator over a
Python Zenoh router, in lockstep, for a given number of steps (no physics, no flight software).

    python bench/bus_floor.py --workers 20 --steps 8640 [--cpu] [--contract] [--sizes-from RUN/run.mcap] [--json]

`--contract` (issue 16): the *message floor of the bus contract* instead: per step the coordinator
publishes what the plant does (a clock tick, a truth, one stimulus per worker on the worker's own
key, with the sizes of drift-20's messages), each worker answers with two messages (a command the
coordinator waits for, and a telemetry), and one more process subscribes to everything (the
recorder's traffic) and only counts. Still no physics, no flight software, no decoding, no
recording: what the run's Zenoh traffic costs by itself on this machine. `--cpu`: CPU ms per step
of each process kind (stderr). `--sizes-from RUN/run.mcap`: the five message sizes are that
recording's mean payload per class (`sizes_from_recording`) instead of drift-20's, so a mission's
floor carries its own messages (paper 000's stimuli are twice drift-20's); the link channel's
traffic and barrier are not in the floor.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from swarmhil.bus.zenoh_bus import endpoint, free_loopback_port, open_client, open_router  # noqa: E402


def worker(router: str, i: int) -> None:
    s = open_client(router)
    pub = s.declare_publisher(f"floor/rep/{i}")
    reply = bytes(200)
    s.declare_subscriber("floor/tick", lambda sample: pub.put(reply))
    s.liveliness().declare_token(f"floor/alive/{i}")
    threading.Event().wait()


# drift-20's message sizes (bytes; measured from a recording): clock, truth, stimulus, command, telemetry
SIZES = {"clock": 178, "truth": 2727, "sense": 160, "act": 47, "tm": 63}
# a recorded topic (the run's key without swarm/<run>/) -> its class in SIZES
CLASSES = (("clock", re.compile(r"clock")), ("truth", re.compile(r"truth")), ("sense", re.compile(r"sc/[^/]+/sense/.+")),
           ("act", re.compile(r"sc/[^/]+/act")), ("tm", re.compile(r"sc/[^/]+/tm")))


def sizes_from_recording(path: str | Path) -> dict[str, int]:
    """Mean payload bytes of each class of SIZES over a recording (topics matched whole); a class the
    recording lacks is an error naming it (the floor would otherwise mix two runs' messages)."""
    from mcap.reader import make_reader

    count = dict.fromkeys(SIZES, 0)
    total = dict.fromkeys(SIZES, 0)
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            for name, pattern in CLASSES:
                if pattern.fullmatch(channel.topic):
                    count[name] += 1
                    total[name] += len(message.data)
                    break
    missing = [name for name, n in count.items() if n == 0]
    if missing:
        raise SystemExit(f"error: {path}: no {', '.join(missing)} messages recorded (needed for --sizes-from)")
    return {name: round(total[name] / count[name]) for name in SIZES}


def contract_worker(router: str, i: int, sizes: dict[str, int]) -> None:
    s = open_client(router)
    act = s.declare_publisher(f"floor/sc/{i}/act")
    tm = s.declare_publisher(f"floor/sc/{i}/tm")
    a, t = bytes(sizes["act"]), bytes(sizes["tm"])

    def on_sense(_sample) -> None:
        act.put(a)
        tm.put(t)
    s.declare_subscriber(f"floor/sc/{i}/sense", on_sense)
    s.liveliness().declare_token(f"floor/alive/{i}")
    threading.Event().wait()


def contract_listener(router: str) -> None:
    s = open_client(router)
    n = [0]

    def on_any(_sample) -> None:
        n[0] += 1
    s.declare_subscriber("floor/**", on_any)
    s.liveliness().declare_token("floor/alive/listener")
    threading.Event().wait()


def coordinator(workers: int, steps: int, cpu: bool = False, contract: bool = False,
                sizes: dict[str, int] | None = None) -> tuple[float, dict[str, float]]:
    """(wall seconds of `steps` lockstep steps, CPU ms per step of each process kind when `cpu`:
    "worker" (each, mean), "workers" (sum), "listener" (`contract`), "coordinator + router")."""
    sizes = sizes or SIZES
    router_ep = endpoint(free_loopback_port())
    router = open_router(router_ep)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    role = ["--contract", "--sizes", json.dumps(sizes)] if contract else []
    procs = [subprocess.Popen([sys.executable, __file__, "--worker", str(i), "--router", router_ep, *role], env=env)
             for i in range(workers)]
    if contract:
        procs.append(subprocess.Popen([sys.executable, __file__, "--worker", "-1", "--router", router_ep, *role], env=env))
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

    s.declare_subscriber("floor/sc/*/act" if contract else "floor/rep/*", on_rep)
    s.liveliness().declare_subscriber("floor/alive/*", on_alive, history=True)
    with cv:
        cv.wait_for(lambda: state["alive"] >= len(procs), timeout=120)
    pub = s.declare_publisher("floor/tick")
    tick = bytes(64)
    if contract:
        clock, truth = s.declare_publisher("floor/clock"), s.declare_publisher("floor/truth")
        senses = [s.declare_publisher(f"floor/sc/{i}/sense") for i in range(workers)]
        c_msg, t_msg, s_msg = bytes(sizes["clock"]), bytes(sizes["truth"]), bytes(sizes["sense"])

        def put_step() -> None:
            clock.put(c_msg)
            truth.put(t_msg)
            for p in senses:
                p.put(s_msg)
    else:
        def put_step() -> None:
            pub.put(tick)
    # untimed warm-up: the first tick right after the workers' tokens reaches only some of them
    # (measured: 13-14 of 20), and the timed loop then stalled 10 s at step 0; rounds until one
    # is answered by every worker (as the run's plant loop, which starts once all are up)
    for _ in range(120):
        with cv:
            state["n"] = 0
        put_step()
        with cv:
            if cv.wait_for(lambda: state["n"] >= workers, timeout=0.5):
                break
        time.sleep(0.2)  # let a late answer land before the next round counts
    else:
        raise SystemExit("error: bus floor: the workers never all answered one tick")
    if cpu:
        from mp_cpu import cpu_s

        c0 = [cpu_s(p.pid) for p in procs], time.process_time()
    lost = 0
    t0 = time.perf_counter()
    for k in range(steps):
        with cv:
            state["n"] = 0
        put_step()
        with cv:
            lost += not cv.wait_for(lambda: state["n"] >= workers, timeout=10)
    wall = time.perf_counter() - t0
    if lost:
        print(f"warning: bus floor: {lost} steps waited 10 s for a lost reply", file=sys.stderr)
    cpu_ms: dict[str, float] = {}
    if cpu:  # CPU ms per step: each worker, and the coordinator with the router (one process)
        w = [(cpu_s(p.pid) - c) / steps * 1e3 for p, c in zip(procs, c0[0])]
        if contract:
            cpu_ms["listener"] = w.pop()
        cpu_ms.update({"workers": sum(w), "worker": sum(w) / len(w),
                       "coordinator + router": (time.process_time() - c0[1]) / steps * 1e3})
        listener = f", listener {cpu_ms['listener']:.3f}" if contract else ""
        print(f"bus floor CPU: workers {cpu_ms['workers']:.3f} ms/step (each {cpu_ms['worker']:.3f}){listener}, coordinator + router "
              f"{cpu_ms['coordinator + router']:.3f} ms/step", file=sys.stderr)
    for p in procs:
        p.kill()  # our own children, by PID
        p.wait()
    s.close()
    router.close()
    return wall, cpu_ms


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=20)
    ap.add_argument("--steps", type=int, default=8640)
    ap.add_argument("--worker", type=int)
    ap.add_argument("--router")
    ap.add_argument("--cpu", action="store_true", help="also print CPU ms per step (stderr)")
    ap.add_argument("--contract", action="store_true", help="the bus contract's messages per step (module docstring)")
    ap.add_argument("--sizes-from", metavar="MCAP", help="--contract with this recording's mean message sizes")
    ap.add_argument("--json", action="store_true", help="also a last line: the result as JSON (wall_s, sizes, cpu_ms_per_step)")
    ap.add_argument("--sizes", help=argparse.SUPPRESS)  # a worker's sizes, as JSON, from its coordinator
    a = ap.parse_args()
    if a.worker is not None:
        if a.contract:
            (contract_listener(a.router) if a.worker < 0 else contract_worker(a.router, a.worker, json.loads(a.sizes)))
        else:
            worker(a.router, a.worker)
        return
    sizes = sizes_from_recording(a.sizes_from) if a.sizes_from else SIZES
    wall, cpu_ms = coordinator(a.workers, a.steps, a.cpu, a.contract or bool(a.sizes_from), sizes)
    kind = "contract" if a.contract or a.sizes_from else "bus"
    print(f"{kind} floor: {a.workers} workers, {a.steps} steps, {wall:.2f} s, {wall / a.steps * 1e3:.3f} ms/step"
          + (f" (sizes {sizes})" if kind == "contract" else ""))
    if a.json:
        print(json.dumps({"floor": kind, "workers": a.workers, "steps": a.steps, "wall_s": wall,
                          "sizes": sizes if kind == "contract" else None, "cpu_ms_per_step": cpu_ms}))


if __name__ == "__main__":
    main()
