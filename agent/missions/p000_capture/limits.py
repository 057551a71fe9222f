"""Actuator limits by norm (paper 000 §4: F_max = 0.1 N, τ_max = 0.01 N·m; NOTES-000: by norm)."""
from __future__ import annotations

import numpy as np


def saturate_norm(vec: np.ndarray, limit: float) -> np.ndarray:
    """Scale `vec` down to Euclidean norm `limit` if it exceeds it (direction kept)."""
    if limit <= 0.0:
        raise ValueError(f"limit must be positive, got {limit}")
    n = float(np.linalg.norm(vec))
    return np.asarray(vec, dtype=float) * (limit / n) if n > limit else np.asarray(vec, dtype=float)
