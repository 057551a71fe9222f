"""Linear relative dynamics in relative orbital elements (ROE) about a near-circular reference.

ROE in metres: roe_m = a (da, dl, dex, dey, dix, diy) (D'Amico 2010 ch. 2; Gaias & D'Amico;
conventions and sign-corrected matrices in shared/seeds/NOTES-002.md). `u` is the mean argument
of latitude of the reference, u(t) = u0 + n t. LVLH: x radial, y along-track, z cross-track.

Keplerian dynamics: d(roe)/dt = A roe + B(u) accel, A[dl, da] = -3/2 n the only nonzero entry
(A^2 = 0, so Phi(t) = I + A t), and B(u) the Gauss-variation input matrix (NOTES-002, times a).
The linear map ROE -> LVLH is exactly the Hill-Clohessy-Wiltshire solution space: propagating ROE
and mapping to LVLH reproduces HCW (tests/test_dynamics_linear.py).
"""
from __future__ import annotations

import functools
import math

import numpy as np

from swarmhil.plant.dynamics.constants import MU_EARTH_M3PS2

DA, DL, DEX, DEY, DIX, DIY = range(6)


def mean_motion(a_m: float) -> float:
    """Keplerian mean motion n = sqrt(mu / a^3) [rad/s]."""
    return float(np.sqrt(MU_EARTH_M3PS2 / a_m**3))


def _as_rows(x: np.ndarray, width: int, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.shape[-1] != width:
        raise ValueError(f"{name} must have last dimension {width}, got shape {arr.shape}")
    return arr


def roe_to_lvlh(roe_m: np.ndarray, u_rad: float, n_radps: float) -> tuple[np.ndarray, np.ndarray]:
    """Near-circular linear map ROE -> LVLH (NOTES-002 'Conventions'); returns pos_m, vel_mps (N, 3).

    x = da - dex cos u - dey sin u        vx = n (dex sin u - dey cos u)
    y = dl + 2 dex sin u - 2 dey cos u    vy = n (-3/2 da + 2 dex cos u + 2 dey sin u)
    z = dix sin u - diy cos u             vz = n (dix cos u + diy sin u)

    Evaluated in exactly this order (each product, then the sums left to right), in few numpy
    calls on whole contiguous arrays (issue 16: this runs every step of a batch run): every
    component is (A + B) + C with a - b written as a + (-b) (the same IEEE result) and -0.0 for
    a missing A or C (-0.0 + b == b, bit for bit); A, B and C of every row are one gather, their
    scale factors (x 1, x 2, x -1.5: the same products as written) one multiplication, the
    trigonometric factors of B and C another.
    """
    roe = _as_rows(roe_m, 6, "roe_m")
    c, s = np.cos(u_rad), np.sin(u_rad)
    if not isinstance(u_rad, float) and np.ndim(u_rad):  # one u per row (broadcast): as written
        da, dl, dex, dey, dix, diy = (roe[..., k] for k in range(6))
        pos = np.stack((da - dex * c - dey * s, dl + 2.0 * dex * s - 2.0 * dey * c, dix * s - diy * c), axis=-1)
        vel = n_radps * np.stack((dex * s - dey * c, -1.5 * da + 2.0 * dex * c + 2.0 * dey * s, dix * c + diy * s),
                                 axis=-1)
        return pos, vel
    lead = roe.shape[:-1]
    take, scale, trig, speed = _lvlh_plan(math.prod(lead), float(n_radps))
    g = np.concatenate((roe.reshape(-1), _NEG_ZERO)).take(take)  # (3, rows, 6): A, B, C (-0.0: the last)
    g *= scale
    g[1:] *= np.array((float(c), float(s), -float(c), -float(s))).take(trig)
    out = np.add(g[0], g[1])
    out += g[2]
    out *= speed  # x 1.0 for the positions (exact), x n for the velocities
    out = out.reshape(lead + (6,))
    return out[..., :3], out[..., 3:]


# per output (x, y, z, vx, vy, vz): A (column, scale), B (column, scale, trig), C (column, scale, trig);
# trig 0: c, 1: s, 2: -c, 3: -s; None: -0.0
_LVLH_A = ((DA, 1.0), (DL, 1.0), None, None, (DA, -1.5), None)
_LVLH_B = ((DEX, 1.0, 2), (DEX, 2.0, 1), (DIX, 1.0, 1), (DEX, 1.0, 1), (DEX, 2.0, 0), (DIX, 1.0, 0))
_LVLH_C = ((DEY, 1.0, 3), (DEY, 2.0, 2), (DIY, 1.0, 2), (DEY, 1.0, 2), (DEY, 2.0, 1), (DIY, 1.0, 1))


_NEG_ZERO = np.array([-0.0])


@functools.lru_cache(maxsize=16)
def _lvlh_plan(rows: int, n_radps: float) -> tuple[np.ndarray, ...]:
    """`roe_to_lvlh`'s gather indices (3, rows, 6) into the flat ROE followed by -0.0, scale
    factors, trigonometric indices (2, rows, 6) and the speed factors (rows, 6) of `rows` rows."""
    col = np.array([[a[0] if a else -1 for a in _LVLH_A], [b[0] for b in _LVLH_B], [c[0] for c in _LVLH_C]])
    sc = np.array([[a[1] if a else 1.0 for a in _LVLH_A], [b[1] for b in _LVLH_B], [c[1] for c in _LVLH_C]])
    tr = np.array([[b[2] for b in _LVLH_B], [c[2] for c in _LVLH_C]])
    take = np.arange(rows)[None, :, None] * 6 + col[:, None, :]
    take[0][:, col[0] < 0] = rows * 6  # the missing A: the -0.0 after the ROE
    out = (take, np.broadcast_to(sc[:, None, :], (3, rows, 6)).copy(), np.broadcast_to(tr[:, None, :], (2, rows, 6)).copy(),
           np.broadcast_to(np.array([1.0, 1.0, 1.0, n_radps, n_radps, n_radps]), (rows, 6)).copy())
    for a in out:
        a.setflags(write=False)
    return out


# lvlh_to_roe for one u: each ROE row is A + B (+ C) of the state (x, y, z, vx/n, vy/n, vz/n), each
# term a coefficient times one state column (a C of -0.0 where the row has two terms: x + -0.0 is x
# for every x, -0.0 and NaN included)
_ROE_A = (0, 1, 0, 0, 2, 2)  # x, y, x, x, z, z
_ROE_B = (4, 3, 3, 3, 5, 5)  # vy, vx, vx, vx, vz, vz (/ n)
_ROE_C = (-1, -1, 4, 4, -1, -1)  # vy / n for the rows of dex, dey; -1: the -0.0 after the state


@functools.lru_cache(maxsize=16)
def _roe_plan(rows: int) -> np.ndarray:
    """`lvlh_to_roe`'s gather indices (3, rows, 6) into the flat state of `rows` rows followed by -0.0."""
    base = np.arange(rows)[:, None] * 6
    take = np.empty((3, rows, 6), dtype=np.intp)
    take[0], take[1] = base + np.array(_ROE_A), base + np.array(_ROE_B)
    take[2] = np.where(np.array(_ROE_C) < 0, rows * 6, base + np.array(_ROE_C))
    take.setflags(write=False)
    return take


def lvlh_to_roe(pos_m: np.ndarray, vel_mps: np.ndarray, u_rad: float, n_radps: float) -> np.ndarray:
    """Exact inverse of `roe_to_lvlh`: the matrix M of NOTES-002 (paper 002 sec. 5, signs restored).

    Rows with state (x, y, vx, vy, z, vz): [4,0,0,2/n,0,0], [0,1,-2/n,0,0,0],
    [3c,0,s/n,2c/n,0,0], [3s,0,-c/n,2s/n,0,0], [0,0,0,0,s,c/n], [0,0,0,0,-c,s/n].
    """
    pos = _as_rows(pos_m, 3, "pos_m")
    vel = _as_rows(vel_mps, 3, "vel_mps")
    if (pos.shape == vel.shape and (isinstance(u_rad, float) or np.ndim(u_rad) == 0)
            and (isinstance(n_radps, float) or np.ndim(n_radps) == 0)):
        # one u (a truth of every step): the products and sums of the rows below in one gather,
        # one product and two sums, in the same order: (k_a x_a + k_b v_b / n) + k_c vy / n
        c, s = float(np.cos(u_rad)), float(np.sin(u_rad))
        lead = pos.shape[:-1]
        rows = pos.size // 3
        state = np.empty(rows * 6 + 1)
        cols = state[:-1].reshape(rows, 6)
        cols[:, :3] = pos.reshape(rows, 3)
        np.divide(vel.reshape(rows, 3), n_radps, out=cols[:, 3:])
        state[-1] = -0.0
        g = state.take(_roe_plan(rows))
        g *= np.array((4.0, 1.0, 3.0 * c, 3.0 * s, s, -c, 2.0, -2.0, s, -c, c, s,
                       1.0, 1.0, 2.0 * c, 2.0 * s, 1.0, 1.0)).reshape(3, 1, 6)
        out = g[0] + g[1]
        out += g[2]
        return out.reshape(lead + (6,))
    c, s = np.cos(u_rad), np.sin(u_rad)
    x, y, z = pos[..., 0], pos[..., 1], pos[..., 2]
    vx, vy, vz = (vel[..., k] / n_radps for k in range(3))
    return np.stack(
        (
            4.0 * x + 2.0 * vy,
            y - 2.0 * vx,
            3.0 * c * x + s * vx + 2.0 * c * vy,
            3.0 * s * x - c * vx + 2.0 * s * vy,
            s * z + c * vz,
            -c * z + s * vz,
        ),
        axis=-1,
    )


def input_matrix(u_rad: float, n_radps: float) -> np.ndarray:
    """a B(u), shape (6, 3): d(roe_m)/dt from (radial, along-track, cross-track) accel [m/s^2].

    a B(u) = 1/n [[0,2,0], [-2,0,0], [sin u, 2cos u, 0], [-cos u, 2sin u, 0], [0,0,cos u], [0,0,sin u]]
    (NOTES-002, Gauss variational equations linearised about a circular orbit).
    """
    c, s = np.cos(u_rad), np.sin(u_rad)
    return (
        np.array(
            [
                [0.0, 2.0, 0.0],
                [-2.0, 0.0, 0.0],
                [s, 2.0 * c, 0.0],
                [-c, 2.0 * s, 0.0],
                [0.0, 0.0, c],
                [0.0, 0.0, s],
            ]
        )
        / n_radps
    )


def state_matrix(n_radps: float) -> np.ndarray:
    """A, shape (6, 6): only A[dl, da] = -3/2 n (Keplerian drift of the mean argument of latitude)."""
    a = np.zeros((6, 6))
    a[DL, DA] = -1.5 * n_radps
    return a


def transition_matrix(n_radps: float, dt_s: float) -> np.ndarray:
    """Phi(dt) = exp(A dt) = I + A dt (A is nilpotent)."""
    return np.eye(6) + state_matrix(n_radps) * dt_s


def zoh_input_matrix(u0_rad: float, n_radps: float, dt_s: float) -> np.ndarray:
    """Gamma = integral_0^dt Phi(dt - s) a B(u0 + n s) ds, shape (6, 3), in closed form.

    With u1 = u0 + n dt, um = (u0 + u1)/2, h = sin(n dt / 2) (differences of sines/cosines written
    as products, so there is no cancellation for small n dt):
      cos u0 - cos u1 = 2 sin um h,   sin u1 - sin u0 = 2 cos um h.
    Rows: da [0, 2dt/n, 0]; dl [-2dt/n, -3/2 dt^2, 0] (the da row through A[dl, da]);
    dex [(cos u0 - cos u1), 2 (sin u1 - sin u0), 0]/n^2; dey [-(sin u1 - sin u0), 2 (cos u0 - cos u1), 0]/n^2;
    dix [0, 0, sin u1 - sin u0]/n^2; diy [0, 0, cos u0 - cos u1]/n^2.
    """
    n = n_radps
    um = u0_rad + 0.5 * n * dt_s
    h = _half_step_sin(n, dt_s)
    dcos = 2.0 * float(np.sin(um)) * h / n**2  # (cos u0 - cos u1) / n^2
    dsin = 2.0 * float(np.cos(um)) * h / n**2  # (sin u1 - sin u0) / n^2
    # one flat tuple of Python floats (the same IEEE products as with numpy scalars), one array call
    return np.array((0.0, 2.0 * dt_s / n, 0.0,
                     -2.0 * dt_s / n, -1.5 * dt_s**2, 0.0,
                     dcos, 2.0 * dsin, 0.0,
                     -dsin, 2.0 * dcos, 0.0,
                     0.0, 0.0, dsin,
                     0.0, 0.0, dcos)).reshape(6, 3)


@functools.lru_cache(maxsize=64)
def _half_step_sin(n_radps: float, dt_s: float) -> float:
    """sin(n dt / 2) of `zoh_input_matrix`: the same for every step of a run."""
    return float(np.sin(0.5 * n_radps * dt_s))


def propagate_roe(
    roe_m: np.ndarray, accel_mps2: np.ndarray, u0_rad: float, n_radps: float, dt_s: float
) -> np.ndarray:
    """Exact solution over dt of d(roe)/dt = A roe + a B(u0 + n t) accel, accel held constant (ZOH).

    roe(dt) = Phi(dt) roe(0) + Gamma(u0, dt) accel (see `zoh_input_matrix`). Shapes (N, 6), (N, 3).
    """
    roe = _as_rows(roe_m, 6, "roe_m")
    accel = _as_rows(accel_mps2, 3, "accel_mps2")
    out = roe.copy()
    out[..., DL] += -1.5 * n_radps * dt_s * roe[..., DA]
    return out + accel @ zoh_input_matrix(u0_rad, n_radps, dt_s).T


class LinearRoePlant:
    """Relative-motion plant on the linear ROE model, same interface as `AbsoluteJ2Plant`.

    The reference is the Keplerian circular orbit of semi-major axis a; `inc_rad` and `raan_rad`
    are kept for interface symmetry (the linear Keplerian model does not depend on them).
    Commands are LVLH accelerations held constant over each step (exact ZOH, `propagate_roe`).
    """

    def __init__(
        self, a_m: float, inc_rad: float, raan_rad: float, u0_rad: float, roe_m: np.ndarray
    ) -> None:
        self.a_m = float(a_m)
        self.inc_rad = float(inc_rad)
        self.raan_rad = float(raan_rad)
        self.n_radps = mean_motion(self.a_m)
        self.u0_rad = float(u0_rad)
        self.roe_m = np.array(_as_rows(roe_m, 6, "roe_m"), dtype=float, ndmin=2)
        self.t_s = 0.0

    def reference_u(self) -> float:
        """Mean argument of latitude of the reference, u0 + n t, wrapped to [0, 2 pi)."""
        return float(np.mod(self.u0_rad + self.n_radps * self.t_s, 2.0 * np.pi))

    def step(self, accel_lvlh_mps2: np.ndarray | None, dt_s: float) -> None:
        """Advance every spacecraft by dt_s with its LVLH acceleration (N, 3) held over the step."""
        accel = np.zeros((len(self.roe_m), 3)) if accel_lvlh_mps2 is None else accel_lvlh_mps2
        accel = np.asarray(accel, dtype=float)
        if accel.shape != (len(self.roe_m), 3):
            raise ValueError(f"accel_lvlh_mps2 must be ({len(self.roe_m)}, 3), got {accel.shape}")
        self.roe_m = propagate_roe(self.roe_m, accel, self.reference_u(), self.n_radps, dt_s)
        self.t_s += dt_s

    def relative_lvlh(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions (N, 3) [m] and velocities (N, 3) [m/s] relative to the reference, in its LVLH."""
        return roe_to_lvlh(self.roe_m, self.reference_u(), self.n_radps)
