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
