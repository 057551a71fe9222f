"""Actuator limits by norm (paper 000 §4: F_max = 0.1 N, τ_max = 0.01 N·m; NOTES-000: by norm)."""
from __future__ import annotations

import math

import numpy as np

from swarmhil.missions.p000_capture.contract import dot3, dot_rows  # noqa: F401  (the flight software's dots: attitude, trigger)


def norm3(vec: np.ndarray) -> float:
    """‖v‖ of one 3-vector: √(v·v) with the dot of `dot3` (the same bits on every CPU, where
    np.linalg.norm's BLAS dot is not) at a fraction of np.linalg.norm's cost."""
    return math.sqrt(dot3(vec, vec))


def saturate_norm(vec: np.ndarray, limit: float) -> np.ndarray:
    """Scale `vec` down to Euclidean norm `limit` if it exceeds it (direction kept)."""
    if limit <= 0.0:
        raise ValueError(f"limit must be positive, got {limit}")
    v = np.asarray(vec, dtype=float)
    n = norm3(v)
    return v * (limit / n) if n > limit else v

