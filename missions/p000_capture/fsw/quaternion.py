"""Unit quaternions, scalar first [q0, qx, qy, qz], Hamilton product (paper 000 §2.1.1, eq. 4–5).

Convention (one place for it): `q` is the attitude of the body relative to LVLH, so a body
vector maps to LVLH as v_L = q ⊗ [0, v_B] ⊗ q*, i.e. `rotate(q, v_B)` = C(q) v_B.
"""
from __future__ import annotations

import math

import numpy as np

from swarmhil.missions.p000_capture.contract import dot3

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for two 3-vectors (np.cross costs ~10x more on single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q."""
    p0, pv = p[0], p[1:]
    q0, qv = q[0], q[1:]
    return np.concatenate(([p0 * q0 - dot3(pv, qv)], p0 * qv + q0 * pv + cross3(pv, qv)))


def conjugate(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def normalise(q: np.ndarray) -> np.ndarray:
    """q / |q| for one 4-vector. |q| is math.hypot's (CPython's own arithmetic and a correctly rounded
    sqrt: the same bits on every CPU), not np.linalg.norm's BLAS dot, whose kernel and so last bit
    differ between processors: a seeded draw of attitudes is then the same on every machine
    (docs/determinism.md)."""
    n = math.hypot(*np.asarray(q, dtype=float).tolist())
    if n == 0.0:
        raise ValueError(f"zero quaternion {q}")
    return np.asarray(q, dtype=float) / n


def to_dcm(q: np.ndarray) -> np.ndarray:
    """C(q): body -> LVLH rotation matrix of a unit quaternion."""
    q0, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - q0 * z), 2 * (x * z + q0 * y)],
        [2 * (x * y + q0 * z), 1 - 2 * (x * x + z * z), 2 * (y * z - q0 * x)],
        [2 * (x * z - q0 * y), 2 * (y * z + q0 * x), 1 - 2 * (x * x + y * y)],
    ])


def rotate(q: np.ndarray, v_body: np.ndarray) -> np.ndarray:
    """Body -> LVLH: C(q) v; `v_body` is (3,) or (K, 3)."""
    return np.asarray(v_body) @ to_dcm(q).T


def from_axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float)
    axis = axis / math.sqrt(dot3(axis, axis))
    return np.concatenate(([np.cos(angle_rad / 2)], np.sin(angle_rad / 2) * axis))


def shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion of the smallest rotation taking unit direction a onto b (paper 000 after eq. 15)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    a = a / math.sqrt(dot3(a, a))
    b = b / math.sqrt(dot3(b, b))
    c = dot3(a, b)
    if c < -1.0 + 1e-12:  # opposite: any axis perpendicular to a
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if math.sqrt(dot3(perp, perp)) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        return np.concatenate(([0.0], perp / math.sqrt(dot3(perp, perp))))
    return normalise(np.concatenate(([1.0 + c], cross3(a, b))))


def omega_matrix(omega: np.ndarray) -> np.ndarray:
    """Ω(ω) of eq. 5, so that q̇ = ½ Ω(ω) q with ω in the body frame (eq. 4)."""
    w1, w2, w3 = omega
    return np.array([
        [0.0, -w1, -w2, -w3],
        [w1, 0.0, w3, -w2],
        [w2, -w3, 0.0, w1],
        [w3, w2, -w1, 0.0],
    ])


def propagate(q: np.ndarray, omega_body: np.ndarray, dt_s: float) -> np.ndarray:
    """Exact attitude update for a body rate held constant over dt: q ⊗ exp(½ ω dt)."""
    w = math.sqrt(dot3(omega_body, omega_body))
    if w * dt_s < 1e-12:
        return q
    return normalise(multiply(q, from_axis_angle(omega_body, w * dt_s)))
