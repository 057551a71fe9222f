"""Sensor pointing: desired attitude and the quaternion PD torque (paper 000 §2.4, eq. 15–18)."""
from __future__ import annotations

import numpy as np

from . import quaternion as quat
from .limits import norm3, saturate_norm

BORESIGHT_BODY = np.array([1.0, 0.0, 0.0])  # sensor axis: body +x (§2.4)


def desired_attitude(position_m: np.ndarray, target_centre_m: np.ndarray) -> np.ndarray:
    """q_d: shortest arc taking body +x onto the line of sight s = x̂_T − x (eq. 15)."""
    los = np.asarray(target_centre_m, dtype=float) - np.asarray(position_m, dtype=float)
    if norm3(los) < 1e-9:
        raise ValueError(f"line of sight undefined: agent at the target centre {position_m}")
    return quat.shortest_arc(BORESIGHT_BODY, los)


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
    c = float(bore @ los / np.linalg.norm(los))
    return float(np.arccos(np.clip(c, -1.0, 1.0)))
