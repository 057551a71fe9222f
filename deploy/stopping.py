"""How a child process of a run learns to stop (issue 17: no orphans, ever).

A stop request comes from SIGTERM (the launcher's orderly stop, or the kernel's PR_SET_PDEATHSIG
when the launcher dies), from a watchdog thread (the launcher or the router is gone), or from code.

Why not `threading.Event` set by a signal handler, as before: a process-directed signal may be
handed by the kernel to any of the process's threads (Zenoh's and ours); CPython then only flags
it, and runs the Python handler when the *main* thread next executes bytecode. A main thread
blocked in an untimed `Event.wait()` never does: one agent in about a dozen SIGKILL-the-launcher
runs stayed alive until its router watchdog fired 8 s later (tests/test_supervision.py). And
`Event.set()` inside a handler takes the Event's lock, which the main thread may hold at that very
moment (inside `Event.wait`): a self-deadlock. So here the handler only stores the signal number
(no lock), and every wait is a timed poll, so the main thread runs a pending handler within
`POLL_S` whichever thread took the signal.
"""
from __future__ import annotations

import logging
import os
import signal
import threading
import time
from typing import Any

POLL_S = 0.2


class Stop:
    """A stop request: `set()` from any thread, `on_signal` as a signal handler (lock-free),
    `is_set()`, and `wait(timeout)` that polls so a pending signal handler runs in the main thread."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.signal = 0  # the signal that asked to stop (0: none)

    def on_signal(self, signum: int, _frame: Any = None) -> None:
        self.signal = signum  # one store: safe in a handler, whatever the main thread holds

    def set(self) -> None:
        self._event.set()

    def is_set(self) -> bool:
        return self.signal != 0 or self._event.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """True once stop is requested; False when `timeout` (seconds) passes first."""
        end = None if timeout is None else time.monotonic() + timeout
        while not self.is_set():
            step = POLL_S if end is None else min(POLL_S, end - time.monotonic())
            if step <= 0:
                return False
            self._event.wait(step)
        return True


def stop_on_signals(*signums: int, ignore: tuple[int, ...] = ()) -> Stop:
    """A Stop set by each of `signums` (from the main thread), with `ignore` ignored, and by the
    parent watchdog below."""
    stop = Stop()
    for s in ignore:
        signal.signal(s, signal.SIG_IGN)
    for s in signums:
        signal.signal(s, stop.on_signal)
    watch_parent(stop)
    return stop


def watch_parent(stop: Stop) -> None:
    """No orphans: stop when the launcher (SWARMHIL_PARENT_PID) is gone. The launcher already asks
    the kernel for a SIGTERM on its death (PR_SET_PDEATHSIG); this watchdog covers a platform
    without it."""
    parent = int(os.environ.get("SWARMHIL_PARENT_PID", "0") or 0)
    if not parent:
        return

    def watch() -> None:
        while not stop.wait(0.5):
            if os.getppid() != parent:
                logging.getLogger("swarmhil.proc").warning("launcher (pid %d) is gone; stopping", parent)
                stop.set()
    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()
