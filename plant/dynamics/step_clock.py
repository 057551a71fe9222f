"""The propagators' clock: t = t_base + k dt while the step dt stays the same.

Counting steps instead of summing dt keeps a long constant-step run free of accumulated
round-off in t (86 400 additions of 0.1 s drift by ~1e-10 s; k dt does not), and gives exactly
the plant's historical clock t = steps_done * dt (plant/world.py) when dt never changes.
"""
from __future__ import annotations


class StepClock:
    def __init__(self, t0_s: float = 0.0) -> None:
        self._t_base = float(t0_s)
        self._dt: float | None = None
        self._k = 0

    @property
    def t_s(self) -> float:
        return self._t_base if self._dt is None else self._t_base + self._k * self._dt

    def advance(self, dt_s: float) -> None:
        """Count one step of dt_s (a new dt starts a new run from the current t)."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        if dt_s != self._dt:
            self._t_base = self.t_s
            self._dt = float(dt_s)
            self._k = 0
        self._k += 1
