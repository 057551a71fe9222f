"""In-memory bus with the interface of the Zenoh bus: the batch mode for Monte Carlo and tests.

`publish` delivers synchronously to every matching subscriber, depth first, in subscription
order. Deliveries triggered from inside a callback are queued and run after the current one, so
the order is the same breadth-first order for every run (determinism) and callbacks never nest.

Two things only a bus inside one process can offer (issue 16, the batch mode's per-step costs):
`wants(key)` tells a publisher whether anyone would receive a sample (a message nobody receives
need not be built), and a publisher may stamp a sample with its simulation time in ns
(`publish(key, payload, t_ns)`), which subscribers declared with `stamped=True` receive as a third
argument (None when the publisher gave none): the recorder then takes its log time from the stamp
instead of decoding the message again.
"""
from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass

from swarmhil.bus.base import LivelinessCallback, SampleCallback, key_matches

log = logging.getLogger("swarmhil.memory")


@dataclass
class _Sub:
    bus: "MemoryBus"
    key_expr: str
    callback: SampleCallback
    active: bool = True
    stamped: bool = False  # callback(key, payload, t_ns)

    def undeclare(self) -> None:
        self.active = False
        self.bus._wanted.clear()
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
    stamps = True  # publish(key, payload, t_ns) reaches subscribe(..., stamped=True) callbacks

    def __init__(self) -> None:
        self._subs: list[_Sub] = []
        self._routes: dict[str, list[_Sub]] = {}  # key -> matching subscribers (cleared on (un)subscribe)
        self._wanted: dict[str, bool] = {}  # key -> `wants(key)` (cleared with them)
        self._watches: list[_Watch] = []
        self._tokens: set[str] = set()
        self._queue: deque[tuple[str, bytes, int | None]] = deque()
        self._dispatching = False
        self.published = 0
        self.callback_errors = 0

    def _route(self, key: str) -> list[_Sub]:
        route = self._routes.get(key)
        if route is None:
            route = self._routes[key] = [s for s in self._subs if key_matches(s.key_expr, key)]
        return route

    def wants(self, key: str) -> bool:
        """True when a sample on `key` would reach a subscriber."""
        w = self._wanted.get(key)
        if w is None:
            w = self._wanted[key] = any(s.active for s in self._route(key))
        return w

    def publish(self, key: str, payload: bytes, t_ns: int | None = None) -> None:
        """Deliver to every matching subscriber; `t_ns` (the sample's simulation time, ns) is passed
        to the stamped ones."""
        self.published += 1
        self._queue.append((key, bytes(payload), t_ns))
        if self._dispatching:
            return
        self._dispatching = True
        try:
            while self._queue:
                k, p, t = self._queue.popleft()
                for sub in self._route(k):
                    if sub.active:
                        try:
                            if sub.stamped:
                                sub.callback(k, p, t)  # type: ignore[call-arg]
                            else:
                                sub.callback(k, p)
                        except Exception:  # as the Zenoh dispatcher: one node's bug never stops the others
                            self.callback_errors += 1
                            log.exception("callback for %s failed", k)
        finally:
            self._dispatching = False

    def subscribe(self, key_expr: str, callback: SampleCallback, stamped: bool = False) -> _Sub:
        sub = _Sub(self, key_expr, callback, stamped=stamped)
        self._subs.append(sub)
        self._routes.clear()
        self._wanted.clear()
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
