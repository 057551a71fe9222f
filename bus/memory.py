"""In-memory bus with the interface of the Zenoh bus: the batch mode for Monte Carlo and tests.

`publish` delivers synchronously to every matching subscriber, depth first, in subscription
order. Deliveries triggered from inside a callback are queued and run after the current one, so
the order is the same breadth-first order for every run (determinism) and callbacks never nest.
"""
from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass

from bus.base import LivelinessCallback, SampleCallback, key_matches

log = logging.getLogger("swarmhil.memory")


@dataclass
class _Sub:
    bus: "MemoryBus"
    key_expr: str
    callback: SampleCallback
    active: bool = True

    def undeclare(self) -> None:
        self.active = False
        if self in self.bus._subs:
            self.bus._subs.remove(self)
            self.bus._routes.clear()


@dataclass
class _Token:
    bus: "MemoryBus"
    key: str
    active: bool = True

    def undeclare(self) -> None:
        if self.active:
            self.active = False
            self.bus._tokens.discard(self.key)
            self.bus._notify_liveliness(self.key, False)


@dataclass
class _Watch:
    bus: "MemoryBus"
    key_expr: str
    callback: LivelinessCallback

    def undeclare(self) -> None:
        if self in self.bus._watches:
            self.bus._watches.remove(self)


class MemoryBus:
    def __init__(self) -> None:
        self._subs: list[_Sub] = []
        self._routes: dict[str, list[_Sub]] = {}  # key -> matching subscribers (cleared on (un)subscribe)
        self._watches: list[_Watch] = []
        self._tokens: set[str] = set()
        self._queue: deque[tuple[str, bytes]] = deque()
        self._dispatching = False
        self.published = 0
        self.callback_errors = 0

    def publish(self, key: str, payload: bytes) -> None:
        self.published += 1
        self._queue.append((key, bytes(payload)))
        if self._dispatching:
            return
        self._dispatching = True
        try:
            while self._queue:
                k, p = self._queue.popleft()
                route = self._routes.get(k)
                if route is None:
                    route = self._routes[k] = [s for s in self._subs if key_matches(s.key_expr, k)]
                for sub in route:
                    if sub.active:
                        try:
                            sub.callback(k, p)
                        except Exception:  # as the Zenoh dispatcher: one node's bug never stops the others
                            self.callback_errors += 1
                            log.exception("callback for %s failed", k)
        finally:
            self._dispatching = False

    def subscribe(self, key_expr: str, callback: SampleCallback) -> _Sub:
        sub = _Sub(self, key_expr, callback)
        self._subs.append(sub)
        self._routes.clear()
        return sub

    def declare_liveliness(self, key: str) -> _Token:
        self._tokens.add(key)
        self._notify_liveliness(key, True)
        return _Token(self, key)

    def watch_liveliness(self, key_expr: str, callback: LivelinessCallback) -> _Watch:
        w = _Watch(self, key_expr, callback)
        self._watches.append(w)
        for k in sorted(self._tokens):
            if key_matches(key_expr, k):
                callback(k, True)
        return w

    def _notify_liveliness(self, key: str, alive: bool) -> None:
        for w in list(self._watches):
            if key_matches(w.key_expr, key):
                w.callback(key, alive)

    def close(self) -> None:
        self._subs.clear()
        self._watches.clear()

    def call_soon(self, fn, *args) -> None:  # type: ignore[no-untyped-def]
        """Run fn(*args) after the deliveries already queued (immediately when idle)."""
        fn(*args)

    def flush(self, timeout_s: float = 5.0) -> bool:
        return True
