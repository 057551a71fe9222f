"""Camera measurements of a neighbour and their models (paper 002 sec. 5, issue 4).

Measurement of one blob: z = (u_px, v_px, s_px) with s = sqrt(area_px).

Area model of a body in nominal attitude (body axes = camera axes) at camera-frame (x, y, z):
a patch dA with normal n at p images to f^2 dA |n.p| / z^3 pixels (solid angle dA|n.p|/|p|^3
times f^2/cos^3 of the off-axis angle), so
    area_px = f^2 / z^2 * (A_z + A_x |x|/z + A_y |y|/z),
with (A_x, A_y, A_z) the silhouette areas along the body axes (SpacecraftShape.projected_areas_m2).
Paper 002's rough range keeps only the face-on term: z = f sqrt(A_true / A_blob).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.agent.camera.model import R_CAM_FROM_LVLH, Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.roe import roe_to_lvlh


@dataclass(frozen=True)
class MeasurementModel:
    """Camera, body shape and the error model of a blob measurement.

    Centroid error per image axis: a body `ext` < 1 px long on that axis lights the same pixels
    wherever it lies within (1 - ext) px, so its centroid is quantised: max(0, 1 - ext)/sqrt(12),
    plus a floor (noise, sub-pixel phase) measured on rendered frames; tests/test_nav_ekf.py
    checks the resulting filter consistency.
    sqrt-area error: the blob's photometric sigma plus a relative shape-model error.
    """

    camera: Camera
    areas_m2: np.ndarray  # (A_x, A_y, A_z), SpacecraftShape.projected_areas_m2
    extent_m: tuple[float, float]  # body size along camera x and y in nominal attitude
    centroid_floor_px: float = 0.025
    area_rel_sigma: float = 0.0025

    @staticmethod
    def for_shape(camera: Camera, shape: SpacecraftShape, **kw) -> "MeasurementModel":
        span = shape.body_side_m + 2.0 * shape.panel_length_m
        height = max(shape.body_side_m, shape.panel_width_m)
        return MeasurementModel(camera, shape.projected_areas_m2, (span, height), **kw)


def rough_position_cam(centroid_px: np.ndarray, area_px: np.ndarray, camera: Camera, area_true_m2: float) -> np.ndarray:
    """Paper 002 sec. 5: depth z = f sqrt(A_true / A_blob), then x, y from the pinhole relation. (M, 3)."""
    z = camera.focal_px * np.sqrt(area_true_m2 / np.maximum(area_px, 1e-9))
    ray = camera.ray(centroid_px)
    return ray * z[:, None]


def roe_position_matrix(u_rad: float, n_radps: float) -> np.ndarray:
    """T (3, 6): LVLH relative position = T @ roe_m (position rows of the ROE -> LVLH map)."""
    return roe_to_lvlh(np.eye(6), u_rad, n_radps)[0].T


_T_CAM: dict[tuple[str, str], np.ndarray] = {}  # (u, n) exactly (float.hex: -0.0 is not 0.0) -> the read-only matrix


def camera_position_matrix(u_rad: float, n_radps: float) -> np.ndarray:
    """(3, 6): camera-frame position of the neighbour = this @ roe_m (nominal pointing). Read-only,
    remembered for the last few (u, n): the spacecraft of a batch run all ask for the same frame's."""
    key = (float(u_rad).hex(), float(n_radps).hex())
    t = _T_CAM.get(key)
    if t is None:
        if len(_T_CAM) >= 8:
            _T_CAM.clear()
        t = _T_CAM[key] = R_CAM_FROM_LVLH @ roe_position_matrix(u_rad, n_radps)
        t.setflags(write=False)
    return t


def predict(model: MeasurementModel, roe_m: np.ndarray, u_rad: float, n_radps: float,
            t_cam: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """h(x) (3,), its Jacobian H (3, 6) w.r.t. roe_m, and the camera-frame position (3,).
    `t_cam`: camera_position_matrix(u_rad, n_radps) if the caller has it already (one per frame)."""
    cam = model.camera
    t = camera_position_matrix(u_rad, n_radps) if t_cam is None else t_cam
    p = t @ roe_m
    x, y, z = p
    f = cam.focal_px
    ax, ay, az = model.areas_m2
    k = az + (ax * abs(x) + ay * abs(y)) / z
    sk = np.sqrt(max(k, 1e-12))
    h = np.array([cam.cx + f * x / z, cam.cy + f * y / z, f * sk / z])
    jp = np.array(
        [
            [f / z, 0.0, -f * x / z**2],
            [0.0, f / z, -f * y / z**2],
            [
                f / z * ax * np.sign(x) / (2.0 * sk * z),
                f / z * ay * np.sign(y) / (2.0 * sk * z),
                -f * sk / z**2 - f / z * (ax * abs(x) + ay * abs(y)) / (2.0 * sk * z**2),
            ],
        ]
    )
    return h, jp @ t, p


def noise_cov(model: MeasurementModel, z_m: float, area_px: float, area_sigma_px: float) -> np.ndarray:
    """R (3, 3) of (u, v, sqrt(area)) for a body at depth z_m (MeasurementModel docstring);
    sigma_s = sigma_A / (2 sqrt A) from the blob's photometric sigma, plus the relative model error."""
    f = model.camera.focal_px
    z = max(z_m, 1e-3)
    su2, sv2 = (
        max(0.0, 1.0 - f * ext / z) ** 2 / 12.0 + model.centroid_floor_px**2 for ext in model.extent_m
    )
    s = np.sqrt(max(area_px, 1e-12))
    ss2 = (area_sigma_px / (2.0 * s)) ** 2 + (model.area_rel_sigma * s) ** 2
    return np.diag([su2, sv2, ss2])


def _pow2(a: np.ndarray) -> np.ndarray:
    """a**2 through libm pow, as `**2` of a numpy float64 scalar in `predict` and `noise_cov` (an
    array's `**2` is a*a, which differs in the last bit now and then)."""
    return np.float_power(a, 2.0)


def predict_many(model: MeasurementModel, roe_m: np.ndarray, t_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`predict` for K states at once (issue 16): roe_m (K, 6) -> h (K, 3), H (K, 3, 6), camera-frame
    position (K, 3). The same products and sums in the same order as `predict`, elementwise over K,
    so each row equals `predict` of that state bit for bit (tests/test_nav_ekf_batched.py)."""
    cam = model.camera
    k_ = len(roe_m)
    p = np.matmul(t_cam, roe_m[:, :, None])[:, :, 0]
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    f = cam.focal_px
    ax, ay, az = model.areas_m2
    z2 = _pow2(z)
    side = ax * np.abs(x) + ay * np.abs(y)  # (each repeated subexpression computed once: the same values)
    k = az + side / z
    sk = np.sqrt(np.maximum(k, 1e-12))
    f_z = f / z
    h = np.empty((k_, 3))
    h[:, 0] = cam.cx + f * x / z
    h[:, 1] = cam.cy + f * y / z
    h[:, 2] = f * sk / z
    two_sk_z = 2.0 * sk * z
    jp = np.zeros((k_, 3, 3))
    jp[:, 0, 0] = f_z
    jp[:, 0, 2] = -f * x / z2
    jp[:, 1, 1] = f_z
    jp[:, 1, 2] = -f * y / z2
    jp[:, 2, 0] = f_z * ax * np.sign(x) / two_sk_z
    jp[:, 2, 1] = f_z * ay * np.sign(y) / two_sk_z
    jp[:, 2, 2] = -f * sk / z2 - f_z * side / (2.0 * sk * z2)
    return h, jp @ t_cam, p


def _noise_diag(model: MeasurementModel, z_m: np.ndarray, area_px: np.ndarray,
                area_sigma_px: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The diagonal of `noise_cov` over arrays, elementwise the same arithmetic: sigma_u^2 and
    sigma_v^2 (the shape of z_m), sigma_s^2 (the shape of area_px)."""
    f = model.camera.focal_px
    z = np.maximum(np.asarray(z_m, dtype=float), 1e-3)
    su2, sv2 = (_pow2(np.maximum(0.0, 1.0 - f * ext / z)) / 12.0 + model.centroid_floor_px**2 for ext in model.extent_m)
    s = np.sqrt(np.maximum(area_px, 1e-12))
    return su2, sv2, _pow2(area_sigma_px / (2.0 * s)) + _pow2(model.area_rel_sigma * s)


def noise_cov_many(model: MeasurementModel, z_m: np.ndarray, area_px: np.ndarray, area_sigma_px: np.ndarray) -> np.ndarray:
    """`noise_cov` for every (depth, blob) pair: z_m (T,), area_px and area_sigma_px (B,) -> R (T, B, 3, 3),
    elementwise the same arithmetic as `noise_cov`."""
    su2, sv2, ss2 = _noise_diag(model, z_m, area_px, area_sigma_px)
    r = np.zeros((len(su2), len(ss2), 3, 3))
    r[:, :, 0, 0] = su2[:, None]
    r[:, :, 1, 1] = sv2[:, None]
    r[:, :, 2, 2] = ss2[None, :]
    return r


def noise_cov_pairs(model: MeasurementModel, z_m: np.ndarray, area_px: np.ndarray, area_sigma_px: np.ndarray) -> np.ndarray:
    """`noise_cov` of P (depth, blob) pairs given pair by pair: z_m, area_px, area_sigma_px (P,) ->
    R (P, 3, 3), elementwise the same arithmetic (each pair's R equals `noise_cov_many`'s)."""
    su2, sv2, ss2 = _noise_diag(model, z_m, area_px, area_sigma_px)
    r = np.zeros((len(su2), 3, 3))
    r[:, 0, 0], r[:, 1, 1], r[:, 2, 2] = su2, sv2, ss2
    return r
