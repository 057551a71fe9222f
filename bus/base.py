"""The bus interface every process uses: Zenoh (bus/zenoh_bus.py) or in-memory (bus/memory.py).

Callbacks receive (key, payload bytes). Each bus delivers callbacks one at a time, in arrival
order, on one dispatcher (never on a Zenoh network thread), so node code needs no locks of its
own for state touched only from callbacks.
"""
from __future__ import annotations

from typing import Callable, Protocol

SampleCallback = Callable[[str, bytes], None]
LivelinessCallback = Callable[[str, bool], None]  # (key, alive)


class Handle(Protocol):
    def undeclare(self) -> None: ...


class Bus(Protocol):
    def publish(self, key: str, payload: bytes) -> None: ...

    def subscribe(self, key_expr: str, callback: SampleCallback) -> Handle: ...

    def declare_liveliness(self, key: str) -> Handle: ...

    def watch_liveliness(self, key_expr: str, callback: LivelinessCallback) -> Handle: ...

    def close(self) -> None: ...


def key_matches(key_expr: str, key: str) -> bool:
    """Zenoh key-expression matching for the forms this project uses: `*` (one chunk), `**` (any)."""
    pat = key_expr.split("/")
    parts = key.split("/")

    def match(i: int, j: int) -> bool:
        if i == len(pat):
            return j == len(parts)
        if pat[i] == "**":
            return any(match(i + 1, jj) for jj in range(j, len(parts) + 1))
        if j == len(parts):
            return False
        if pat[i] == "*" or pat[i] == parts[j]:
            return match(i + 1, j + 1)
        return False

    return match(0, 0)
