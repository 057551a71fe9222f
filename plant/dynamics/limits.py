"""Actuator limits on force, acceleration or torque commands, pure functions over (N, 3) arrays.

Two models (issue 11, per-spacecraft actuator limits):
- `per_axis`: each body axis saturates on its own at +-max (three opposed thruster pairs or
  three reaction wheels): u_i <- clip(u_i, -max_i, max_i). The direction of the command may turn.
- `norm`: the vector is scaled down to the ball |u| <= max, direction kept (one gimballed
  thruster, or a torque budget shared by the axes): u <- u min(1, max/|u|).
`max` is a scalar, one value per craft (N,), or, for `per_axis`, one value per craft and axis (N, 3).
"""
from __future__ import annotations

import math
from typing import Literal

import numpy as np

LimitMode = Literal["per_axis", "norm"]
LIMIT_MODES: tuple[str, ...] = ("per_axis", "norm")


def _check_max(max_value: float | np.ndarray) -> np.ndarray | float:
    if isinstance(max_value, float):  # the common case, checked without numpy (a step of a batch run)
        if not (math.isfinite(max_value) and max_value >= 0.0):
            raise ValueError(f"actuator limit must be finite and >= 0, got {max_value!r}")
        return max_value
    m = np.asarray(max_value, dtype=float)
    if np.any(~np.isfinite(m)) or np.any(m < 0.0):
        raise ValueError(f"actuator limit must be finite and >= 0, got {max_value!r}")
    return m


def limit_per_axis(command: np.ndarray, max_value: float | np.ndarray) -> np.ndarray:
    """Saturate each axis: clip(u, -max, max); max scalar, (N,) or (N, 3). Returns a new (N, 3) array."""
    u = np.asarray(command, dtype=float)
    m = _check_max(max_value)
    if not isinstance(m, float) and m.ndim == 1:
        m = m[:, None]
    return u.clip(-m, m)  # np.clip's ufunc without np.clip's Python wrapper (1.3 against 2.7 us; issue 16)


def limit_norm(command: np.ndarray, max_value: float | np.ndarray) -> np.ndarray:
    """Scale each row into the ball |u| <= max, direction kept; max scalar or (N,). Returns a new array."""
    return limit_norm_rows(command, max_value)[0]


def limit_norm_rows(command: np.ndarray, max_value: float | np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """`limit_norm` and, when no row is over its limit, the (..., ) norms of the rows it returns
    (`row_norm` of u * 1.0 is `row_norm` of u: the same squares), else None."""
    u = np.asarray(command, dtype=float)
    m = _check_max(max_value)  # (a float, or an array of floats)
    if not isinstance(m, float) and m.ndim > 1:
        raise ValueError(f"a norm limit is one value per craft, got shape {m.shape}")
    norm = row_norm(u)
    over = norm > m
    if not np.count_nonzero(over):  # nobody over the limit: every scale 1.0 (u * 1.0, the same product)
        return u * 1.0, norm
    scale = np.ones_like(norm)
    np.divide(m, norm, out=scale, where=over)
    return u * scale[..., None], None


def row_norm(u: np.ndarray) -> np.ndarray:
    """|u| of each row (..., 3) of a float64 array: what `np.linalg.norm(u, axis=-1)` computes,
    sqrt of the sum of the squares along the last axis, the same float64, without its wrapper."""
    return np.sqrt(np.add.reduce(u * u, axis=-1))


def limit_command(command: np.ndarray, max_value: float | np.ndarray, mode: str) -> np.ndarray:
    """`limit_per_axis` or `limit_norm` by name (`LIMIT_MODES`)."""
    if mode == "per_axis":
        return limit_per_axis(command, max_value)
    if mode == "norm":
        return limit_norm(command, max_value)
    raise ValueError(f"unknown actuator limit mode {mode!r}; known: {', '.join(LIMIT_MODES)}")


def force_to_accel(force_n: np.ndarray, mass_kg: float | np.ndarray) -> np.ndarray:
    """a = F / m per craft; force (N, 3) [N], mass scalar or (N,) [kg] (constant mass)."""
    m = np.asarray(mass_kg, dtype=float)
    if np.any(~(m > 0.0)):
        raise ValueError(f"mass_kg must be > 0, got {mass_kg!r}")
    f = np.asarray(force_n, dtype=float)
    return f / (m[..., None] if m.ndim else m)
