"""How the plant synchronises with the flight software: two implementations of one interface.

`Lockstep`: step k ends when every live agent's command for step k has arrived (or, on a stall,
the long `[supervision].stall_timeout_s` passes): deterministic whatever the OS scheduling and load. `RealTime`: step k ends at its wall
deadline t0 + (k+1) * step / speed; what has not arrived is a missed deadline, and the plant
holds that agent's previous command (DESIGN.md "Time").
"""
from __future__ import annotations

import threading
import time
from typing import Protocol


class CommandBox:
    """Thread-safe mailbox of commands for the current step, filled from bus callbacks."""

    def __init__(self) -> None:
        self._cv = threading.Condition()
        self._step = -1
        self._cmds: dict[str, object] = {}

    def open(self, step: int) -> None:
        with self._cv:
            self._step = step
            self._cmds = {}

    def put(self, step: int, sc: str, cmd: object) -> bool:
        """Store a command; False when it is for another step than the open one (late or early)."""
        with self._cv:
            if step != self._step:
                return False
            self._cmds[sc] = cmd
            self._cv.notify_all()
            return True

    def wake(self) -> None:
        with self._cv:
            self._cv.notify_all()

    def wait(self, expected: "callable", deadline_wall: float) -> dict[str, object]:  # type: ignore[valid-type]
        """Wait until expected() (a set of ids) is a subset of what arrived, or the deadline."""
        with self._cv:
            while True:
                if expected() <= self._cmds.keys():
                    break
                remaining = deadline_wall - time.monotonic()
                if remaining <= 0:
                    break
                self._cv.wait(remaining)
            got = dict(self._cmds)
            self._step = -1
            return got


class Pacer(Protocol):
    name: str

    def start(self) -> None: ...

    def deadline(self, step: int) -> float: ...

    def after_step(self, step: int) -> None: ...


class Lockstep:
    name = "lockstep"

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s

    def start(self) -> None:
        pass

    def deadline(self, step: int) -> float:
        return time.monotonic() + self.timeout_s

    def after_step(self, step: int) -> None:
        pass


class RealTime:
    name = "realtime"

    def __init__(self, step_s: float, speed: float) -> None:
        self.period_s = step_s / speed
        self.t0 = 0.0
        self.late_steps = 0

    def start(self) -> None:
        self.t0 = time.monotonic()

    def deadline(self, step: int) -> float:
        return self.t0 + (step + 1) * self.period_s

    def after_step(self, step: int) -> None:
        wait = self.t0 + (step + 1) * self.period_s - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        else:
            self.late_steps += 1
