"""Cost of the run's authentication and access control (bus/acl.py) on a lockstep-like exchange.

A "plant" publishes a stimulus to each of N agents; each agent answers with a command; the plant
waits for all N (one step). Through the run's router, once open and once with the per-run
user/password dictionary and the default-deny ACL. Prints steps/s of each.

    .venv/bin/python bench/acl_overhead.py [N] [STEPS]
"""
from __future__ import annotations

import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from swarmhil.bus.acl import make_run_security  # noqa: E402
from swarmhil.bus.keys import Keys  # noqa: E402
from swarmhil.bus.zenoh_bus import ZenohBus, endpoint, free_loopback_port, open_router  # noqa: E402


def bench(n: int, steps: int, secure: bool) -> float:
    run = "bench"
    k = Keys(run)
    ids = [f"a{i}" for i in range(n)]
    with tempfile.TemporaryDirectory() as d:
        sec = make_run_security(Path(d), run, ["plant", *[f"agent-{i}" for i in ids]]) if secure else None
        ep = endpoint(free_loopback_port())
        router = open_router(ep, sec.router_overrides() if sec else None)
        cred = (lambda u: sec.credential(u)) if sec else (lambda u: None)
        plant = ZenohBus(ep, credential=cred("plant"))
        agents = [ZenohBus(ep, credential=cred(f"agent-{i}")) for i in ids]
        got = threading.Semaphore(0)
        plant.subscribe(k.act_all, lambda _k, _p: got.release())
        for i, a in zip(ids, agents):
            a.subscribe(k.sense(i, "rel"), lambda _k, p, a=a, i=i: a.publish(k.act(i), p))
        time.sleep(0.5)
        payload = bytes(64)
        t0 = time.perf_counter()
        for _ in range(steps):
            for i in ids:
                plant.publish(k.sense(i, "rel"), payload)
            for _ in ids:
                if not got.acquire(timeout=10):
                    raise RuntimeError("a command did not come back")
        rate = steps / (time.perf_counter() - t0)
        for b in (plant, *agents):
            b.close()
        router.close()
        return rate


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    steps = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    for secure in (False, True, False, True):
        print(f"N={n} {'secure' if secure else 'open  '}: {bench(n, steps, secure):8.0f} steps/s", flush=True)
