"""Search → chase → dock (paper 000 §3, Events 1–3) and the search-mode forces (eq. 21–22)."""
from __future__ import annotations

import numpy as np


def bounce_force(position_m: np.ndarray, box_m: float, f_thr_n: float) -> np.ndarray:
    """F_bnc (eq. 21–22): −F_thr per axis beyond +box, +F_thr below −box, else 0."""
    p = np.asarray(position_m, dtype=float)
    return np.where(p > box_m, -f_thr_n, np.where(p < -box_m, f_thr_n, 0.0))


def random_force(rng: np.random.Generator, alpha: float, f_thr_n: float) -> np.ndarray:
    """F_rnd = α F_thr rand(1) along a random unit direction (NOTES-000: a scalar has no direction)."""
    d = rng.normal(size=3)
    return alpha * f_thr_n * float(rng.uniform()) * d / np.linalg.norm(d)


def next_mode(mode: str, detected: bool, received_estimate: bool, estimate_settled: bool,
              at_slot: bool) -> str:
    """Event 1 (own detection) or Event 2 (a neighbour's estimate received): search → chase.
    Event 3 (estimate settled and the agent at its slot): chase → dock. Dock is kept."""
    if mode == "search" and (detected or received_estimate):
        return "chase"
    if mode == "chase" and estimate_settled and at_slot:
        return "dock"
    return mode
