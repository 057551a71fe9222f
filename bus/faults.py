"""Fault injection on a process's bus: delayed deliveries and delayed publishes (issue 10).

The races of a distributed run (a packet reaching the link channel before the plant's tick of its
step; an agent whose transmissions reach the channel after its command) depend on timing that an
undisturbed run on an idle machine seldom shows. This wrapper makes them happen on purpose, over
the real Zenoh bus, so tests can assert the outcome does not depend on them.

Enabled per process by the environment variable `SWARMHIL_FAULTS`, a JSON object keyed by process
name (`plant`, `recorder`, `channel`, `agent-<id>`):

    {"channel": {"delay_rx": {"clock": 0.05}}, "agent-sc02": {"delay_tx": {"isl/tx/": 0.3}}}

`delay_rx` {key fragment: seconds}: samples whose key contains the fragment reach this process's
callbacks that much later. `delay_tx` {key fragment: seconds}: this process's publishes on such keys
leave that much later (other publishes are not held back). Order among delayed items is kept.
Unset, nothing is wrapped and nothing costs anything.
"""
from __future__ import annotations

import heapq
import itertools
import json
import os
import threading
import time
from typing import Any, Callable

ENV = "SWARMHIL_FAULTS"


class DelayLine:
    """One thread that runs fn(*args) at their due times, in (due, submission) order."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Callable[..., None], tuple[Any, ...]]] = []
        self._count = itertools.count()
        self._cv = threading.Condition()
        threading.Thread(target=self._run, name="fault-delay", daemon=True).start()

    def put(self, delay_s: float, fn: Callable[..., None], *args: Any) -> None:
        with self._cv:
            heapq.heappush(self._heap, (time.monotonic() + delay_s, next(self._count), fn, args))
            self._cv.notify()

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._heap or self._heap[0][0] > time.monotonic():
                    self._cv.wait(None if not self._heap else max(0.0, self._heap[0][0] - time.monotonic()))
                _due, _n, fn, args = heapq.heappop(self._heap)
            fn(*args)


def _match(rules: dict[str, float], key: str) -> float:
    return max((d for frag, d in rules.items() if frag in key), default=0.0)


class FaultyBus:
    """A bus (bus/base.py interface) whose deliveries and publishes on chosen keys are delayed."""

    def __init__(self, inner: Any, delay_rx: dict[str, float] | None = None,
                 delay_tx: dict[str, float] | None = None) -> None:
        self.inner = inner
        self.delay_rx = {str(k): float(v) for k, v in (delay_rx or {}).items()}
        self.delay_tx = {str(k): float(v) for k, v in (delay_tx or {}).items()}
        self._line = DelayLine()
        self.delayed_rx = 0
        self.delayed_tx = 0

    def publish(self, key: str, payload: bytes) -> None:
        d = _match(self.delay_tx, key)
        if d > 0:
            self.delayed_tx += 1
            self._line.put(d, self.inner.publish, key, payload)
        else:
            self.inner.publish(key, payload)

    def subscribe(self, key_expr: str, callback: Callable[[str, bytes], None]) -> Any:
        def on_sample(key: str, payload: bytes) -> None:
            d = _match(self.delay_rx, key)
            if d > 0:
                self.delayed_rx += 1
                self._line.put(d, self.inner.call_soon, callback, key, payload)
            else:
                callback(key, payload)

        return self.inner.subscribe(key_expr, on_sample)

    def __getattr__(self, name: str) -> Any:  # liveliness, call_soon, flush, close: the inner bus's
        return getattr(self.inner, name)


def faults_for(process: str, env: dict[str, str] | None = None) -> dict[str, Any] | None:
    """This process's rules from SWARMHIL_FAULTS, or None; a malformed value is a clear error."""
    raw = (env if env is not None else os.environ).get(ENV)
    if not raw:
        return None
    try:
        doc = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{ENV} is not JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{ENV} must be a JSON object keyed by process name (got {type(doc).__name__})")
    rules = doc.get(process)
    if rules is None:
        return None
    unknown = set(rules) - {"delay_rx", "delay_tx"}
    if unknown:
        raise ValueError(f"{ENV}[{process!r}]: unknown fault kinds {sorted(unknown)}; known: delay_rx, delay_tx")
    return rules


def wrap(bus: Any, process: str) -> Any:
    """The bus itself, or a FaultyBus when SWARMHIL_FAULTS names this process."""
    rules = faults_for(process)
    return bus if rules is None else FaultyBus(bus, rules.get("delay_rx"), rules.get("delay_tx"))
