"""plant/contact.py: what the contact monitor computes keeps its bits (issue 29)."""
from __future__ import annotations

import numpy as np


def test_rotate_to_body_keeps_its_bits() -> None:
    """Issue 29: plant/contact.py `_rotate_to_body` with the quaternion's components as Python floats
    gives the bits of the same formula on numpy scalars (NaN, ±inf, -0.0, subnormals)."""
    from swarmhil.plant.contact import _rotate_to_body

    def before(q_wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
        w, x, y, z = q_wxyz
        r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        return v @ r

    rng = np.random.default_rng(35)
    for _ in range(500):
        q = rng.normal(size=4)
        q /= np.sqrt((q * q).sum())
        q[rng.random(4) < 0.1] = rng.choice([np.nan, np.inf, -0.0, 5e-324, 0.0])
        v = rng.normal(0, 100, (int(rng.integers(1, 8)), 3))
        with np.errstate(all="ignore"):
            assert _rotate_to_body(q, v).tobytes() == before(q, v).tobytes()
    assert _rotate_to_body(np.array([1.0, 0.0, 0.0, 0.0]), v).tobytes() == before(np.array([1.0, 0.0, 0.0, 0.0]), v).tobytes()
