"""Extended Kalman filter on the relative ROE of each tracked neighbour (issue 4).

State x = roe_m of the neighbour relative to the observer (k minus j), metres, with covariance P.
Dynamics (paper 002 Eq. 2, Keplerian, agent.roe): x' = A x + a B(u) (a_k - a_j). Over a frame
interval dt with the observer's own acceleration a_j held (ZOH) and the neighbour's a_k unknown
(white, sigma_acc per axis):
    x+ = Phi x - Gamma a_j,   P+ = Phi P Phi^T + Gamma (sigma_acc^2 I) Gamma^T,
    Phi = I + A dt (A nilpotent),  Gamma = Phi(dt/2) a B(u_mid) dt (midpoint rule, O((n dt)^2)).
Measurement per blob: (u, v, sqrt(area)) through the pinhole and the area model of
agent.nav.measure; noise from the blob's photometric sigma and the camera model.
Why an EKF and not a UKF: the measurement is smooth and nearly linear over the covariance of a
converged track (sub-pixel, a few per cent in range); the Jacobian is cheap and closed-form.

Tracks: an unassigned blob starts a tentative track (position from bearing and the area model,
velocity prior N(0, sigma_v^2 I)); association is global nearest neighbour on the Mahalanobis
distance of the innovation, gated at chi^2_3(99.9 %) = 16.27; a track is confirmed after
`confirm_hits` updates; deleted after `max_misses` consecutive misses (a tentative one after one),
or when its prediction leaves the field of view or range by a margin.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.blob.blobs import Blobs
from agent.camera.model import R_LVLH_FROM_CAM, Camera
from agent.camera.shape import SpacecraftShape
from agent.nav.associate import assign
from agent.nav.base import Track
from agent.nav.measure import MeasurementModel, noise_cov, predict
from agent.roe import input_matrix, lvlh_to_roe, roe_to_lvlh, state_matrix


@dataclass(frozen=True)
class EkfConfig:
    accel_sigma_mps2: float = 1e-6
    init_velocity_sigma_mps: float = 0.2
    init_range_rel_sigma: float = 0.05
    gate_chi2: float = 16.27
    confirm_hits: int = 3
    max_misses: int = 5
    fov_margin: float = 1.2  # delete a coasting track predicted beyond margin * half FOV
    range_margin: float = 1.5  # ... or beyond margin * the camera's max range


@dataclass
class _EkfTrack:
    track_id: str
    x: np.ndarray
    p: np.ndarray
    age: int = 0
    hits: int = 1
    misses: int = 0
    blob_index: int = -1


def transition(n_radps: float, dt_s: float) -> np.ndarray:
    return np.eye(6) + state_matrix(n_radps) * dt_s


def input_gamma(u0_rad: float, a_m: float, n_radps: float, dt_s: float) -> np.ndarray:
    """Gamma (6, 3): metres of roe per m/s^2 held over dt (midpoint rule)."""
    um = u0_rad + 0.5 * n_radps * dt_s
    return transition(n_radps, 0.5 * dt_s) @ (a_m * input_matrix(um, a_m, n_radps)) * dt_s


def lvlh_to_roe_matrices(u_rad: float, n_radps: float) -> tuple[np.ndarray, np.ndarray]:
    """(Mp, Mv), each (6, 3): roe_m = Mp @ pos + Mv @ vel (the linear map M of paper 002 sec. 5)."""
    z = np.zeros((3, 3))
    mp = lvlh_to_roe(np.eye(3), z, u_rad, n_radps).T
    mv = lvlh_to_roe(z, np.eye(3), u_rad, n_radps).T
    return mp, mv


class EkfNavigator:
    name = "ekf"

    def __init__(self, camera: Camera, shape: SpacecraftShape, a_m: float, n_radps: float, config: EkfConfig | None = None, model: MeasurementModel | None = None) -> None:
        self.camera = camera
        self.model = model or MeasurementModel.for_shape(camera, shape)
        self.a_m, self.n = a_m, n_radps
        self.cfg = config or EkfConfig()
        self.tracks: list[_EkfTrack] = []
        self._t: float | None = None
        self._u: float | None = None
        self._next_id = 0

    # -- filter steps -------------------------------------------------------------------------
    def _predict(self, dt: float, u0: float, own_accel: np.ndarray | None) -> None:
        if dt <= 0.0:
            return
        phi = transition(self.n, dt)
        gam = input_gamma(u0, self.a_m, self.n, dt)
        q = self.cfg.accel_sigma_mps2**2 * gam @ gam.T
        shift = np.zeros(6) if own_accel is None else gam @ np.asarray(own_accel, dtype=float)
        for tr in self.tracks:
            tr.x = phi @ tr.x - shift
            tr.p = phi @ tr.p @ phi.T + q

    def _innovations(self, u_rad: float, blobs: Blobs):
        """Per track: h, H, and per (track, blob): innovation nu (T, M, 3), S (T, M, 3, 3)."""
        t, m = len(self.tracks), len(blobs)
        zs = np.stack((blobs.centroid_px[:, 0], blobs.centroid_px[:, 1], np.sqrt(np.maximum(blobs.area_px, 1e-12))), axis=1)
        hs, jacs, depth = [], [], []
        for tr in self.tracks:
            h, jac, p = predict(self.model, tr.x, u_rad, self.n)
            hs.append(h)
            jacs.append(jac)
            depth.append(p[2])
        nu = zs[None, :, :] - np.array(hs).reshape(t, 1, 3)
        s = np.empty((t, m, 3, 3))
        for i, tr in enumerate(self.tracks):
            hph = jacs[i] @ tr.p @ jacs[i].T
            for j in range(m):
                s[i, j] = hph + noise_cov(self.model, depth[i], blobs.area_px[j], blobs.area_sigma_px[j])
        return zs, hs, jacs, depth, nu, s

    def _new_track(self, u_rad: float, centroid: np.ndarray, area: float, area_sigma: float) -> _EkfTrack:
        cam, mdl, cfg = self.camera, self.model, self.cfg
        tx, ty = (centroid[0] - cam.cx) / cam.focal_px, (centroid[1] - cam.cy) / cam.focal_px
        ax, ay, az = mdl.areas_m2
        z = cam.focal_px * np.sqrt((az + ax * abs(tx) + ay * abs(ty)) / max(area, 1e-12))
        p_cam = z * np.array([tx, ty, 1.0])
        r = noise_cov(mdl, z, area, area_sigma)
        rel_z2 = (area_sigma / (2.0 * area)) ** 2 + mdl.area_rel_sigma**2 + cfg.init_range_rel_sigma**2
        jac = np.array([[z, 0.0, tx], [0.0, z, ty], [0.0, 0.0, 1.0]])
        p_cam_cov = jac @ np.diag([r[0, 0] / cam.focal_px**2, r[1, 1] / cam.focal_px**2, rel_z2 * z * z]) @ jac.T
        pos = R_LVLH_FROM_CAM @ p_cam
        pos_cov = R_LVLH_FROM_CAM @ p_cam_cov @ R_LVLH_FROM_CAM.T
        mp, mv = lvlh_to_roe_matrices(u_rad, self.n)
        x = mp @ pos
        p = mp @ pos_cov @ mp.T + cfg.init_velocity_sigma_mps**2 * mv @ mv.T
        tr = _EkfTrack(f"e{self._next_id}", x, p)
        self._next_id += 1
        return tr

    def _alive(self, tr: _EkfTrack, u_rad: float) -> bool:
        cfg = self.cfg
        if tr.misses == 0:
            return True
        if tr.hits < cfg.confirm_hits or tr.misses > cfg.max_misses:
            return False
        _, _, p = predict(self.model, tr.x, u_rad, self.n)
        tan_x, tan_y = (np.tan(a) for a in self.camera.half_fov_rad)
        return bool(
            p[2] > 0
            and abs(p[0]) <= cfg.fov_margin * tan_x * p[2]
            and abs(p[1]) <= cfg.fov_margin * tan_y * p[2]
            and np.linalg.norm(p) <= cfg.range_margin * self.camera.max_range_m
        )

    # -- the Navigator interface --------------------------------------------------------------
    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None) -> list[Track]:
        if self._t is not None:
            self._predict(t_s - self._t, self._u, own_accel_mps2)
        self._t, self._u = t_s, u_rad
        for tr in self.tracks:
            tr.age += 1
            tr.blob_index = -1
        pairs: list[tuple[int, int]] = []
        if self.tracks and len(blobs):
            zs, hs, jacs, depth, nu, s = self._innovations(u_rad, blobs)
            d2 = np.einsum("tmi,tmi->tm", nu, np.linalg.solve(s, nu[..., None])[..., 0])
            pairs = assign(d2, self.cfg.gate_chi2)
            for i, j in pairs:
                tr = self.tracks[i]
                gain = tr.p @ jacs[i].T @ np.linalg.inv(s[i, j])
                ikh = np.eye(6) - gain @ jacs[i]
                r = s[i, j] - jacs[i] @ tr.p @ jacs[i].T
                tr.x = tr.x + gain @ nu[i, j]
                tr.p = ikh @ tr.p @ ikh.T + gain @ r @ gain.T
                tr.hits += 1
                tr.misses = 0
                tr.blob_index = j
        matched_t = {i for i, _ in pairs}
        for i, tr in enumerate(self.tracks):
            if i not in matched_t:
                tr.misses += 1
        self.tracks = [tr for tr in self.tracks if self._alive(tr, u_rad)]
        matched_b = {j for _, j in pairs}
        for j in range(len(blobs)):
            if j not in matched_b:
                tr = self._new_track(u_rad, blobs.centroid_px[j], float(blobs.area_px[j]), float(blobs.area_sigma_px[j]))
                tr.blob_index = j
                self.tracks.append(tr)
        return [self._output(tr, u_rad) for tr in self.tracks if tr.hits >= self.cfg.confirm_hits]

    def _output(self, tr: _EkfTrack, u_rad: float) -> Track:
        pos, vel = roe_to_lvlh(tr.x, u_rad, self.n)
        return Track(tr.track_id, tr.x.copy(), pos, vel, tr.p.copy(), tr.age, tr.hits, tr.blob_index)
