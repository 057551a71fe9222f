"""Per-row arithmetic of (N, 3) arrays that equals, row by row, the 1-D numpy call a per-spacecraft
`step` makes, bit for bit (a batch path's rule, issue 16/29; docs/determinism.md)."""
from __future__ import annotations

import numpy as np


def row_dots(a: np.ndarray) -> np.ndarray:
    """(N,) a_r . a_r of each row of an (N, 3) float64 array, each by the BLAS `ddot` that
    `a[r].dot(a[r])` (and so `np.linalg.norm(a[r])`, its square root) calls: numpy's `np.vecdot`
    (numpy >= 2) and `np.matmul` of a (1, 3) row by a (3, 1) column both call numpy's `DOUBLE_dot`
    with the row's stride, as the 1-D dot does (tests/missions/test_p001_lattice.py and
    test_p003_units.py, byte for byte)."""
    if _VECDOT is not None:
        return _VECDOT(a, a)
    return np.matmul(a[:, None, :], a[:, :, None]).reshape(len(a))


_VECDOT = getattr(np, "vecdot", None)  # (numpy >= 2: the same per-row DOUBLE_dot, fewer numpy calls)
