"""Global nearest-neighbour association of blobs to tracks with a gate."""
from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def assign(cost: np.ndarray, gate: float) -> list[tuple[int, int]]:
    """Pairs (row, col) minimising the summed cost over pairs with cost <= gate (Hungarian)."""
    if cost.size == 0:
        return []
    big = 1e6 * (1.0 + gate)
    c = np.where(cost <= gate, cost, big)
    rows, cols = linear_sum_assignment(c)
    return [(int(r), int(k)) for r, k in zip(rows, cols) if c[r, k] < big]
