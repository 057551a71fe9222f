"""LVLH frame of an orbiting body and the ECI -> LVLH relative-state transform.

LVLH (Hill / RSW, Vallado sec. 3.3; Schaub & Junkins sec. 14.2): x radial (r/|r|), z along the
orbit normal (h/|h|, h = r x v), y = z x x (along-track, = velocity direction on a circular orbit).
The frame turns with angular velocity, in LVLH components,
    omega = (|r| a.z / |h|, 0, |h| / |r|^2),
where a.z is the out-of-plane (cross-track) part of the body's acceleration: d z/dt = (r x a)_perp/|h|
gives omega_x; d x/dt = v_perp/|r| gives omega_z. For Keplerian motion omega_x = 0; J2 makes it
about 1e-6 rad/s at 500 km (mm/s over a km of separation), so it is kept when `a` is given.
"""
from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (broadcasting); faster than np.cross for small arrays (and than
    np.stack of the three components, which it equals)."""
    c0 = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    c1 = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    c2 = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    out = np.empty(np.shape(c0) + (3,), dtype=np.result_type(c0, c1, c2))
    out[..., 0], out[..., 1], out[..., 2] = c0, c1, c2
    return out


def lvlh_basis(r_m: np.ndarray, v_mps: np.ndarray) -> np.ndarray:
    """Rotation ECI -> LVLH, shape (..., 3, 3): rows are x_hat, y_hat, z_hat in ECI (v_lvlh = R @ v_eci)."""
    r_m = np.asarray(r_m, dtype=float)
    v_mps = np.asarray(v_mps, dtype=float)
    h = cross(r_m, v_mps)
    x_hat = r_m / np.linalg.norm(r_m, axis=-1, keepdims=True)
    z_hat = h / np.linalg.norm(h, axis=-1, keepdims=True)
    y_hat = cross(z_hat, x_hat)
    return np.stack((x_hat, y_hat, z_hat), axis=-2)


def lvlh_angular_velocity(
    r_m: np.ndarray, v_mps: np.ndarray, accel_mps2: np.ndarray | None = None
) -> np.ndarray:
    """Angular velocity of the LVLH frame in LVLH components (module docstring), shape (..., 3)."""
    r_m = np.asarray(r_m, dtype=float)
    v_mps = np.asarray(v_mps, dtype=float)
    h = cross(r_m, v_mps)
    h_norm = np.linalg.norm(h, axis=-1)
    r_norm = np.linalg.norm(r_m, axis=-1)
    omega = np.zeros(np.broadcast_shapes(r_m.shape, v_mps.shape))
    omega[..., 2] = h_norm / r_norm**2
    if accel_mps2 is not None:
        a_cross = np.sum(np.asarray(accel_mps2, dtype=float) * h, axis=-1) / h_norm
        omega[..., 0] = r_norm * a_cross / h_norm
    return omega


def eci_to_lvlh(
    r_ref_m: np.ndarray,
    v_ref_mps: np.ndarray,
    r_m: np.ndarray,
    v_mps: np.ndarray,
    a_ref_mps2: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Relative position and velocity of bodies (r, v) in the rotating LVLH frame of the reference.

    rho = R (r - r_ref);  rho_dot = R (v - v_ref) - omega x rho  (transport theorem), with omega from
    `lvlh_angular_velocity(r_ref, v_ref, a_ref)`; pass the reference's acceleration `a_ref_mps2` to
    include the out-of-plane frame rotation (J2), otherwise omega = (0, 0, |h|/|r|^2).
    Shapes: reference (3,), bodies (N, 3) (or anything broadcasting with them).
    """
    rot = lvlh_basis(r_ref_m, v_ref_mps)
    omega = lvlh_angular_velocity(r_ref_m, v_ref_mps, a_ref_mps2)
    dr = np.asarray(r_m, dtype=float) - np.asarray(r_ref_m, dtype=float)
    dv = np.asarray(v_mps, dtype=float) - np.asarray(v_ref_mps, dtype=float)
    rho = np.einsum("...ij,...j->...i", rot, dr)
    rho_dot = np.einsum("...ij,...j->...i", rot, dv) - cross(omega, rho)
    return rho, rho_dot


def lvlh_vector_to_eci(r_m: np.ndarray, v_mps: np.ndarray, vec_lvlh: np.ndarray) -> np.ndarray:
    """Rotate vectors (..., 3) given in each body's own LVLH frame to ECI: R^T vec.

    Written without forming R (hot path of the plant's right-hand side), using
    y_hat = (h x r)/(|h| |r|) = (|r|^2 v - (r.v) r)/(|h| |r|):
      R^T f = (f_x - f_y (r.v)/|h|)/|r| r + f_y |r|/|h| v + f_z/|h| h.
    """
    h = cross(r_m, v_mps)
    r_norm = np.sqrt(np.einsum("...i,...i->...", r_m, r_m))
    inv_h = 1.0 / np.sqrt(np.einsum("...i,...i->...", h, h))
    r_dot_v = np.einsum("...i,...i->...", r_m, v_mps)
    f_y_h = vec_lvlh[..., 1] * inv_h
    c_r = (vec_lvlh[..., 0] - f_y_h * r_dot_v) / r_norm
    c_v = f_y_h * r_norm
    c_h = vec_lvlh[..., 2] * inv_h
    return c_r[..., None] * r_m + c_v[..., None] * v_mps + c_h[..., None] * h


def argument_of_latitude(r_m: np.ndarray, v_mps: np.ndarray) -> float:
    """Osculating (true) argument of latitude of one body (r, v shape (3,)), in [0, 2 pi).

    Angle from the ascending node n = z_ECI x h to r in the orbit plane (Vallado sec. 2.5);
    for an equatorial orbit it is measured from ECI x (true longitude).
    """
    r, v = r_m, v_mps
    h = cross(r, v)
    h_hat = h / np.linalg.norm(h)
    node = np.array([-h[1], h[0], 0.0])
    node_norm = np.linalg.norm(node)
    if node_norm < 1e-12 * np.linalg.norm(h):  # equatorial: measure from ECI x
        return float(np.mod(np.arctan2(r[1], r[0]) * np.sign(h[2]), 2.0 * np.pi))
    node /= node_norm
    return float(np.mod(np.arctan2(np.dot(cross(node, r), h_hat), np.dot(node, r)), 2.0 * np.pi))
