"""The flight software's own model of near-circular relative motion in ROE (paper 002 section 2).

Independent on purpose of `plant/dynamics/roe_linear.py` (DESIGN.md: flight model vs truth model);
a test checks that the two agree. Conventions as in NOTES-002 (signs restored from the paper):

- ROE in metres: roe_m = a * (da, dl, dex, dey, dix, diy), `u` the reference mean argument of
  latitude, `n` the mean motion; LVLH x radial, y along-track, z cross-track.
- ROE -> LVLH (D'Amico):
  x = a(da - dex cos u - dey sin u)      vx = a n(dex sin u - dey cos u)
  y = a(dl + 2 dex sin u - 2 dey cos u)  vy = a n(-3/2 da + 2 dex cos u + 2 dey sin u)
  z = a(dix sin u - diy cos u)           vz = a n(dix cos u + diy sin u)
- LVLH -> ROE: the paper's matrix M (section 5) with its signs restored.
- Keplerian dynamics, Eq. (2): d(dalpha)/dt = A dalpha + B(u) u_c, A[dl, da] = -3/2 n,
  B(u) = 1/(a n) [[0,2,0], [-2,0,0], [sin u, 2cos u, 0], [-cos u, 2 sin u, 0], [0,0,cos u], [0,0,sin u]].
"""
from __future__ import annotations

import numpy as np

ROE_NAMES: tuple[str, ...] = ("da", "dl", "dex", "dey", "dix", "diy")


def roe_to_lvlh(roe_m: np.ndarray, u_rad: float, n_radps: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear map ROE (metres, (6,) or (N,6)) -> LVLH position (m) and velocity (m/s), NOTES-002."""
    r = np.asarray(roe_m, dtype=float)
    da, dl, dex, dey, dix, diy = (r[..., i] for i in range(6))
    c, s = np.cos(u_rad), np.sin(u_rad)
    pos_m = np.stack([da - dex * c - dey * s, dl + 2.0 * dex * s - 2.0 * dey * c, dix * s - diy * c], axis=-1)
    vel_mps = n_radps * np.stack(
        [dex * s - dey * c, -1.5 * da + 2.0 * dex * c + 2.0 * dey * s, dix * c + diy * s], axis=-1
    )
    return pos_m, vel_mps


def lvlh_to_roe(pos_m: np.ndarray, vel_mps: np.ndarray, u_rad: float, n_radps: float) -> np.ndarray:
    """Inverse map LVLH -> ROE in metres (the paper's M of section 5 with signs restored, NOTES-002)."""
    p = np.asarray(pos_m, dtype=float)
    v = np.asarray(vel_mps, dtype=float) / n_radps
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    c, s = np.cos(u_rad), np.sin(u_rad)
    out = np.empty(np.broadcast_shapes(x.shape, vx.shape) + (6,))  # filled column by column (np.stack's cost, not its values)
    out[..., 0] = 4.0 * x + 2.0 * vy
    out[..., 1] = y - 2.0 * vx
    out[..., 2] = 3.0 * x * c + vx * s + 2.0 * vy * c
    out[..., 3] = 3.0 * x * s - vx * c + 2.0 * vy * s
    out[..., 4] = z * s + vz * c
    out[..., 5] = -z * c + vz * s
    return out


def observer_roe_rows(rel_position_m: np.ndarray, rel_velocity_mps: np.ndarray, u_rad: float,
                      n_radps: float) -> np.ndarray:
    """`lvlh_to_roe(-rel_position_m, -rel_velocity_mps, u, n)` of (P, 3) rows, bit for bit: the same
    products and sums in the same order, in few numpy calls (issue 16: a batch run does this for
    every visible pair every step). Each ROE is (A + B) [+ C] with a - b written as a + (-b) (the
    same IEEE result; -b is a product with a negated factor, or the negated column itself): one
    gather of the operands, their scale factors, then their trigonometric factors."""
    p_ = len(rel_position_m)
    x = np.empty((p_, 7))  # x, y, z, vx, vy, vz (observer relative to neighbour, v / n), -z
    np.negative(rel_position_m, out=x[:, 0:3])
    np.divide(np.negative(rel_velocity_mps), n_radps, out=x[:, 3:6])
    x[:, 6] = rel_position_m[:, 2]  # -z: the sign bit flipped twice, as np.negative(-z) (NaN too)
    c, s = float(np.cos(u_rad)), float(np.sin(u_rad))
    t = x.take(_OPS, axis=1)
    t *= _OP_SCALES
    t *= np.array((1.0, 1.0, c, s, s, c, 1.0, 1.0, s, -c, c, s, c, s))
    out = np.add(t[:, 0:6], t[:, 6:12])
    out[:, 2:4] += t[:, 12:14]
    return out


# A: 4x, y, (3x) c, (3x) s, z s, (-z) c;  B: 2vy, (-2) vx, vx s, vx (-c), vz c, vz s;  C (ROE 2, 3): (2vy) c, (2vy) s
_OPS = np.array([0, 1, 0, 0, 2, 6, 4, 3, 3, 3, 5, 5, 4, 4])
_OP_SCALES = np.array([4.0, 1.0, 3.0, 3.0, 1.0, 1.0, 2.0, -2.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0])


def state_matrix(n_radps: float) -> np.ndarray:
    """Keplerian plant matrix A of Eq. (2): the only nonzero entry is d(dl)/dt = -3/2 n da."""
    a_mat = np.zeros((6, 6))
    a_mat[1, 0] = -1.5 * n_radps
    return a_mat


def input_matrix(u_rad: float, a_m: float, n_radps: float) -> np.ndarray:
    """Control input matrix B(u) of Eq. (2), dimensionless ROE rate per m/s^2 (signs per NOTES-002).

    Multiply by a_m for the rate of the ROE in metres.
    """
    c, s = np.cos(u_rad), np.sin(u_rad)
    return np.array(
        [
            [0.0, 2.0, 0.0],
            [-2.0, 0.0, 0.0],
            [s, 2.0 * c, 0.0],
            [-c, 2.0 * s, 0.0],
            [0.0, 0.0, c],
            [0.0, 0.0, s],
        ]
    ) / (a_m * n_radps)
