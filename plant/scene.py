"""`scene` sensor stimulus (issue 4): what an observer's camera would image, and nothing else.

Camera frame: x right, y down, z along the boresight. A nominally pointing spacecraft looks
along-track (+y LVLH, paper 002 sec. 3.1) with image "down" towards the Earth (-x LVLH):
    p_cam = R_CAM_FROM_LVLH @ p_lvlh,  R_CAM_FROM_LVLH rows: x_c = -z_L, y_c = -x_L, z_c = +y_L.
A spacecraft's body frame coincides with its camera frame (camera along body +z), so the nominal
attitude body -> LVLH is R_CAM_FROM_LVLH^T.

Pointing error: a small rotation vector theta (rad) in the nominal camera frame turning the camera
away from its commanded axes: R_cam_from_lvlh = Rot(theta)^T @ R_cam_from_lvlh_commanded.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

R_CAM_FROM_LVLH: np.ndarray = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
NOMINAL_BODY_TO_LVLH: np.ndarray = R_CAM_FROM_LVLH.T
SPACECRAFT_RADIUS_M = 0.61  # 1.2 m x 0.2 m x 0.2 m spacecraft of paper 002 sec. 5 (agent.camera.shape)


@dataclass
class Scene:
    """Bodies near enough to matter: ids (M,), position_cam_m (M, 3), rot_body_to_cam (M, 3, 3)."""

    ids: list[str]
    position_cam_m: np.ndarray
    rot_body_to_cam: np.ndarray


def camera_from_lvlh(observer_body_to_lvlh: np.ndarray | None = None, pointing_error_rad: np.ndarray | None = None) -> np.ndarray:
    """Rotation LVLH -> actual camera frame of an observer (its attitude and pointing error)."""
    r = R_CAM_FROM_LVLH if observer_body_to_lvlh is None else np.asarray(observer_body_to_lvlh, dtype=float).T
    if pointing_error_rad is not None and np.any(pointing_error_rad):
        r = Rotation.from_rotvec(np.asarray(pointing_error_rad, dtype=float)).as_matrix().T @ r
    return r


def scene(
    observer_pos_m: np.ndarray,
    others_pos_m: np.ndarray,
    others_ids: list[str],
    *,
    observer_body_to_lvlh: np.ndarray | None = None,
    others_body_to_lvlh: np.ndarray | None = None,
    pointing_error_rad: np.ndarray | None = None,
    max_range_m: float = 500.0,
    tan_half_fov: float | None = 0.54,
    body_radius_m: float = SPACECRAFT_RADIUS_M,
) -> Scene:
    """Poses, in the observer's actual camera frame, of the others within `max_range_m` (centre
    distance) that could put a pixel in the image: in front of the camera and, if `tan_half_fov`
    is given, within the square field of view grown by the body's angular radius."""
    rel_lvlh = np.asarray(others_pos_m, dtype=float).reshape(-1, 3) - np.asarray(observer_pos_m, dtype=float)
    r_cl = camera_from_lvlh(observer_body_to_lvlh, pointing_error_rad)
    p = rel_lvlh @ r_cl.T
    rng = np.linalg.norm(p, axis=1)
    keep = (rng <= max_range_m) & (p[:, 2] > -body_radius_m)
    if tan_half_fov is not None:
        grow = body_radius_m * np.sqrt(1.0 + tan_half_fov**2)
        keep &= (np.abs(p[:, 0]) <= tan_half_fov * p[:, 2] + grow) & (np.abs(p[:, 1]) <= tan_half_fov * p[:, 2] + grow)
    idx = np.flatnonzero(keep)
    if others_body_to_lvlh is None:
        rot = np.broadcast_to(r_cl @ NOMINAL_BODY_TO_LVLH, (len(idx), 3, 3)).copy()
    else:
        rot = r_cl @ np.asarray(others_body_to_lvlh, dtype=float).reshape(-1, 3, 3)[idx]
    return Scene([others_ids[k] for k in idx], p[idx], rot)


def matrix_to_quaternion_wxyz(rot: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> scalar-first quaternions (..., 4) for the wire (ScenePose)."""
    q = Rotation.from_matrix(np.asarray(rot, dtype=float).reshape(-1, 3, 3)).as_quat()  # x, y, z, w
    return np.concatenate((q[:, 3:], q[:, :3]), axis=1).reshape(np.shape(rot)[:-2] + (4,))
