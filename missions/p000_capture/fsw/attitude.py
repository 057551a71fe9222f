"""Sensor pointing: desired attitude and the quaternion PD torque (paper 000 §2.4, eq. 15–18)."""
from __future__ import annotations

import math

import numpy as np

from . import quaternion as quat
from .limits import dot3, dot_rows, norm3, saturate_norm

BORESIGHT_BODY = np.array([1.0, 0.0, 0.0])  # sensor axis: body +x (§2.4)


def line_of_sight(position_m: np.ndarray, target_centre_m: np.ndarray) -> np.ndarray:
    """s = x̂_T − x (eq. 15); raises ValueError where it has no direction (the agent at the centre)."""
    los = np.asarray(target_centre_m, dtype=float) - np.asarray(position_m, dtype=float)
    if norm3(los) < 1e-9:
        raise ValueError(f"line of sight undefined: agent at the target centre {position_m}")
    return los


def desired_attitude(position_m: np.ndarray, target_centre_m: np.ndarray) -> np.ndarray:
    """q_d: shortest arc taking body +x onto the line of sight s = x̂_T − x (eq. 15)."""
    return quat.shortest_arc(BORESIGHT_BODY, line_of_sight(position_m, target_centre_m))


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """quaternion.cross3 of (N, 3) rows (a may be one row), the same expression per component."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def desired_attitudes(los_m: np.ndarray) -> np.ndarray:
    """`desired_attitude` of N lines of sight (rows of `line_of_sight`) at once, row i the bits of
    row i's: quaternion.shortest_arc from body +x written out over arrays (unit directions by the
    dot's sum and a correctly rounded sqrt, |q| by math.hypot per row, as `normalise`)."""
    los = np.asarray(los_m, dtype=float)
    a = BORESIGHT_BODY[None, :] / math.sqrt(dot3(BORESIGHT_BODY, BORESIGHT_BODY))
    b = los / np.sqrt(dot_rows(los, los))[:, None]
    c = dot_rows(np.broadcast_to(a, b.shape), b)
    q = np.concatenate([(1.0 + c)[:, None], _cross_rows(a, b)], axis=1)
    norms = np.array([math.hypot(*row) for row in q.tolist()])
    with np.errstate(invalid="ignore", divide="ignore"):  # (|q| = 0 only opposite the boresight: below)
        out = q / norms[:, None]
    for i in np.flatnonzero(c < -1.0 + 1e-12).tolist():  # opposite: shortest_arc's own branch
        out[i] = quat.shortest_arc(BORESIGHT_BODY, los[i])
    return out


def pointing_torques(q: np.ndarray, omega_body_radps: np.ndarray, q_d: np.ndarray, inertia_kgm2: float,
                     k_q: float, k_w: float, torque_max_nm: float) -> np.ndarray:
    """`pointing_torque` of N spacecraft (rows) with isotropic inertia J = j I and gains K_q = k_q I,
    K_ω = k_ω I (CaptureParams'), row i the bits of row i's: eq. 16 and 18 written out over arrays
    (a diagonal matrix times a vector is one product per component), saturated by norm."""
    if torque_max_nm <= 0.0:
        raise ValueError(f"limit must be positive, got {torque_max_nm}")
    q, w, q_d = (np.asarray(x, dtype=float) for x in (q, omega_body_radps, q_d))
    p0, pv = q_d[:, 0], -q_d[:, 1:]              # q_d* (conjugate)
    q0, qv = q[:, 0], q[:, 1:]
    e0 = p0 * q0 - dot_rows(pv, qv)             # quaternion.multiply(q_d*, q)
    ev = p0[:, None] * qv + q0[:, None] * pv + _cross_rows(pv, qv)
    ev = np.where((e0 < 0.0)[:, None], -ev, ev)  # scalar part made non-negative (eq. 16)
    tau = _cross_rows(w, inertia_kgm2 * w) - k_q * ev - k_w * w
    n = np.sqrt(dot_rows(tau, tau))
    over = n > torque_max_nm
    tau[over] = tau[over] * (torque_max_nm / n[over])[:, None]
    return tau


def error_quaternion(q: np.ndarray, q_d: np.ndarray) -> np.ndarray:
    """q_e = q_d* ⊗ q with scalar part made non-negative (eq. 16)."""
    q_e = quat.multiply(quat.conjugate(q_d), q)
    return -q_e if q_e[0] < 0.0 else q_e


def pointing_torque(q: np.ndarray, omega_body_radps: np.ndarray, q_d: np.ndarray,
                    inertia_kgm2: np.ndarray, k_q: np.ndarray, k_w: np.ndarray,
                    torque_max_nm: float) -> np.ndarray:
    """τ = ω×Jω − K_q q_e,vec − K_ω ω (eq. 18, ω_d = 0), saturated by norm at τ_max.

    K_q multiplies the vector part of q_e (NOTES-000: eq. 18 as printed multiplies a 4-vector).
    """
    w = np.asarray(omega_body_radps, dtype=float)
    q_e = error_quaternion(q, q_d)
    tau = quat.cross3(w, inertia_kgm2 @ w) - k_q @ q_e[1:] - k_w @ w
    return saturate_norm(tau, torque_max_nm)


def rate_damping_torque(omega_body_radps: np.ndarray, inertia_kgm2: np.ndarray,
                        k_w: np.ndarray, torque_max_nm: float,
                        omega_ref_body_radps: np.ndarray | None = None) -> np.ndarray:
    """Search-mode rate control: τ = ω×Jω − K_ω (ω − ω_ref), ω_ref = 0 (hold, NOTES-000: pointing
    starts in chase, §2.4) or a slow scan rate about body z that sweeps the sensor cone round."""
    w = np.asarray(omega_body_radps, dtype=float)
    err = w if omega_ref_body_radps is None else w - omega_ref_body_radps
    return saturate_norm(quat.cross3(w, inertia_kgm2 @ w) - k_w @ err, torque_max_nm)


def pointing_error_rad(q: np.ndarray, position_m: np.ndarray, target_m: np.ndarray) -> float:
    """Angle between body +x (in LVLH) and the line of sight to `target_m`."""
    bore = quat.rotate(q, BORESIGHT_BODY)
    los = np.asarray(target_m, dtype=float) - np.asarray(position_m, dtype=float)
    c = dot3(bore, los) / norm3(los)
    return float(np.arccos(np.clip(c, -1.0, 1.0)))
