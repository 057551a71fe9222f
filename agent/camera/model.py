"""Pinhole camera of paper 002 section 5 and the frames it lives in (flight-software copy).

Camera frame: x right, y down, z along the boresight. Pixel (row i, col j) covers
u in [j, j+1), v in [i, i+1); the principal point (cx, cy) = (W/2, H/2) lies on a pixel corner.
Projection (Sturm 2014, paper 002 Eq. for p_imm): u = cx + f X/Z, v = cy + f Y/Z.

Nominal pointing (paper 002 sec. 3.1): boresight along +y LVLH (along-track, looking forward),
image "down" towards the Earth (-x LVLH, radial), so image "right" is -z LVLH (cross-track):
    p_cam = R_CAM_FROM_LVLH @ p_lvlh,  rows = camera axes in LVLH: x_c = -z, y_c = -x, z_c = +y.
The paper's p_x = f x/y, p_y = f z/y are then (cy - v) and (cx - u): same geometry, other signs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

R_CAM_FROM_LVLH: np.ndarray = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
R_LVLH_FROM_CAM: np.ndarray = R_CAM_FROM_LVLH.T


@dataclass(frozen=True)
class Camera:
    """Square pinhole camera; defaults are the paper's 1080 x 1080 px, f = 1000 px, 500 m range."""

    width_px: int = 1080
    height_px: int = 1080
    focal_px: float = 1000.0
    max_range_m: float = 500.0

    @property
    def cx(self) -> float:
        return self.width_px / 2.0

    @property
    def cy(self) -> float:
        return self.height_px / 2.0

    @property
    def half_fov_rad(self) -> tuple[float, float]:
        """Half angles (horizontal, vertical): atan(540/1000) = 28.37 deg for the paper's camera."""
        return (float(np.arctan(self.cx / self.focal_px)), float(np.arctan(self.cy / self.focal_px)))

    def project(self, p_cam_m: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame points -> (..., 2) pixel coordinates (u, v); needs Z > 0."""
        p = np.asarray(p_cam_m, dtype=float)
        z = p[..., 2]
        return np.stack((self.cx + self.focal_px * p[..., 0] / z, self.cy + self.focal_px * p[..., 1] / z), axis=-1)

    def ray(self, uv_px: np.ndarray) -> np.ndarray:
        """(..., 2) pixel coordinates -> (..., 3) camera-frame direction with Z = 1 (inverse of `project`)."""
        uv = np.asarray(uv_px, dtype=float)
        return np.stack(
            ((uv[..., 0] - self.cx) / self.focal_px, (uv[..., 1] - self.cy) / self.focal_px, np.ones(uv.shape[:-1])),
            axis=-1,
        )

    def in_fov(self, p_cam_m: np.ndarray) -> np.ndarray:
        """True where a point projects inside the image rectangle and lies in front of the camera."""
        p = np.asarray(p_cam_m, dtype=float)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.cx + self.focal_px * p[..., 0] / z
            v = self.cy + self.focal_px * p[..., 1] / z
            return (z > 0) & (u >= 0) & (u <= self.width_px) & (v >= 0) & (v <= self.height_px)


def quat_to_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """Scalar-first Hamilton unit quaternion(s) (..., 4) -> rotation matrix (..., 3, 3) (same sense)."""
    q = np.asarray(q_wxyz, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), axis=-1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), axis=-1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), axis=-1),
        ),
        axis=-2,
    )
