"""Paper 002 section 5's rough navigation: blobs of two successive frames -> relative state.

- Range from area, z = f sqrt(A_true / A_blob). `range_model` says what A_true is:
  "silhouette" (default): the area the known shape shows along the blob's line of sight,
  A_true = A_z + A_x |x/z| + A_y |y/z| (agent.nav.measure, the EKF's own area model; x/z, y/z from
  the centroid), so a neighbour off the boresight, which also shows its radial faces obliquely,
  is not taken for a nearer one; "face_on": the paper's literal A_true = A_z, biased by up to 6.8 %
  at the edge of the field of view (docs/camera-navigation.md). x, y from the pinhole relation.
- Nearest-neighbour association between the two newest frames, on the image position predicted
  with the blob's last image velocity, gated at `gate_px`, one-to-one (Hungarian).
- Velocity from the two newest frames (NOTES-002: the printed difference uses the future frame).
  `velocity` = "dynamics" (default): the relative ROE at the newest frame that reproduce both
  frames' positions under the known relative dynamics (paper 002 Eq. 2, Keplerian; the observer's
  own commanded acceleration held over the interval as the known input, the neighbour's unknown
  control taken as zero): with T(u) the ROE -> LVLH position map, Phi, Gamma the transition and
  input matrices over dt (agent.nav.ekf),
      [ T(u_t) ; T(u_{t-dt}) Phi^-1 ] alpha_t = [ r_t ; r_{t-dt} - T(u_{t-dt}) Phi^-1 Gamma a_j ],
  six equations for the six ROE: the finite difference without its lag (a plain difference is the
  mean velocity over the interval, dt/2 late, which the relative orbit's curvature and the
  observer's own thrust turn into metres of a*da and a*de). "difference": the paper's causal
  finite difference, zdot = dz/dt, xdot = z/f du/dt + (u - cx)/f zdot, ydot likewise, then
  LVLH -> ROE with the paper's M (agent.roe.lvlh_to_roe).
A track is output from its second frame on (it needs a velocity) and dropped at its first miss.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.agent.blob.blobs import Blobs
from swarmhil.agent.camera.model import R_LVLH_FROM_CAM, Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav.associate import assign
from swarmhil.agent.nav.base import Track
from swarmhil.agent.nav.ekf import input_gamma, transition
from swarmhil.agent.nav.measure import roe_position_matrix, rough_position_cam
from swarmhil.agent.roe import lvlh_to_roe, roe_to_lvlh

RANGE_MODELS = ("silhouette", "face_on")
VELOCITY_MODELS = ("dynamics", "difference")
CHOICES = {"range_model": RANGE_MODELS, "velocity": VELOCITY_MODELS}  # [nav.params] that name a choice


@dataclass
class _Prev:
    track_id: str
    t_s: float
    centroid_px: np.ndarray
    p_cam_m: np.ndarray
    image_vel_pxps: np.ndarray | None
    age: int
    hits: int


def silhouette_area_m2(ray: np.ndarray, areas_m2: np.ndarray) -> np.ndarray:
    """A_z + A_x |x/z| + A_y |y/z| (M,): the area of a body in nominal attitude seen along the rays
    (M, 3) with z = 1 (agent.nav.measure module docstring)."""
    ax, ay, az = (float(a) for a in areas_m2)
    return az + ax * np.abs(ray[:, 0]) + ay * np.abs(ray[:, 1])


def _frame_system(u1_rad: float, dt_s: float, a_m: float, n_radps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lhs (6, 6), T(u0) Phi^-1 (3, 6), Gamma (6, 3)) of `two_frame_roe` for one frame interval; the
    navigators of a batch step share one reference u and dt, so the last few are remembered
    (read-only; the same values whether remembered or not)."""
    key = (u1_rad, dt_s, a_m, n_radps)
    hit = _SYSTEMS.get(key)
    if hit is None:
        u0_rad = u1_rad - n_radps * dt_s
        t0 = roe_position_matrix(u0_rad, n_radps) @ np.linalg.inv(transition(n_radps, dt_s))
        lhs = np.vstack((roe_position_matrix(u1_rad, n_radps), t0))
        hit = (lhs, t0, input_gamma(u0_rad, a_m, n_radps, dt_s))
        for m in hit:
            m.setflags(write=False)
        if len(_SYSTEMS) >= 8:
            _SYSTEMS.clear()
        _SYSTEMS[key] = hit
    return hit


_SYSTEMS: dict[tuple[float, float, float, float], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def two_frame_roe(r0_m: np.ndarray, r1_m: np.ndarray, u1_rad: float, dt_s: float | np.ndarray, a_m: float,
                  n_radps: float, own_accel_mps2: np.ndarray | None) -> np.ndarray:
    """The ROE (metres, neighbour relative to observer) at the newest frame that reproduce the LVLH
    positions r0 (dt before) and r1 (at the reference's mean argument of latitude u1; u0 = u1 - n dt)
    under Eq. 2 with the observer's own thrust a_j held over dt (module docstring): the 6 x 6 solve.
    r0_m, r1_m (P, 3) or (3,); dt_s a scalar or (P,); returns (P, 6) or (6,)."""
    r0, r1 = np.atleast_2d(r0_m), np.atleast_2d(r1_m)
    dts = np.broadcast_to(np.asarray(dt_s, dtype=float), (len(r1),))
    out = np.empty((len(r1), 6))
    same = dts.min() == dts.max() if len(dts) else True
    groups = [(float(dts[0]), slice(None))] if same and len(dts) else \
        [(dt, np.flatnonzero(dts == dt)) for dt in np.unique(dts).tolist()]
    for dt, rows in groups:  # one system per interval (a frame's pairs share one)
        lhs, t0, gamma = _frame_system(u1_rad, dt, a_m, n_radps)
        rhs = np.concatenate((r1[rows], r0[rows]), axis=1)
        if own_accel_mps2 is not None:
            rhs[:, 3:] -= t0 @ (gamma @ np.asarray(own_accel_mps2, dtype=float))
        out[rows] = np.linalg.solve(lhs, rhs.T).T
    return out if np.ndim(r1_m) == 2 else out[0]


class RoughNavigator:
    name = "rough"

    def __init__(self, camera: Camera, shape: SpacecraftShape, a_m: float, n_radps: float, gate_px: float = 30.0,
                 range_model: str = "silhouette", velocity: str = "dynamics") -> None:
        if range_model not in RANGE_MODELS:
            raise ValueError(f"[nav.params].range_model must be one of {RANGE_MODELS} (got {range_model!r})")
        if velocity not in VELOCITY_MODELS:
            raise ValueError(f"[nav.params].velocity must be one of {VELOCITY_MODELS} (got {velocity!r})")
        self.camera = camera
        self.areas_m2 = np.asarray(shape.projected_areas_m2, dtype=float)
        self.area_true_m2 = float(self.areas_m2[2])
        self.a_m, self.n = a_m, n_radps
        self.gate_px = gate_px
        self.range_model, self.velocity = range_model, velocity
        self._prev: list[_Prev] = []
        self._next_id = 0

    def positions_cam(self, blobs: Blobs) -> np.ndarray:
        """(M, 3) camera-frame positions of the blobs: range from area under `range_model`."""
        cam = self.camera
        if self.range_model == "face_on":
            return rough_position_cam(blobs.centroid_px, blobs.area_px, cam, self.area_true_m2)
        ray = cam.ray(blobs.centroid_px).reshape(-1, 3)
        z = cam.focal_px * np.sqrt(silhouette_area_m2(ray, self.areas_m2) / np.maximum(blobs.area_px, 1e-9))
        return ray * z[:, None]

    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None) -> list[Track]:
        cam = self.camera
        p_cam = self.positions_cam(blobs)
        pred = np.array(
            [p.centroid_px + (0.0 if p.image_vel_pxps is None else p.image_vel_pxps * (t_s - p.t_s)) for p in self._prev]
        ).reshape(-1, 2)
        cost = np.linalg.norm(pred[:, None, :] - blobs.centroid_px[None, :, :], axis=2)
        pairs = assign(cost, self.gate_px)
        out: list[Track] = []
        nxt: list[_Prev] = []
        used = set()
        if pairs:  # every matched pair of the frame at once
            prevs = [self._prev[k] for k, _ in pairs]
            ms = [m for _, m in pairs]
            used.update(ms)
            dt = np.array([t_s - prev.t_s for prev in prevs])
            c, z = blobs.centroid_px[ms], p_cam[ms, 2]
            duv = (c - np.array([prev.centroid_px for prev in prevs])) / dt[:, None]
            pos = p_cam[ms] @ R_LVLH_FROM_CAM.T  # a signed permutation: exact per row
            if self.velocity == "dynamics":
                pos0 = np.array([prev.p_cam_m for prev in prevs]) @ R_LVLH_FROM_CAM.T
                roe = two_frame_roe(pos0, pos, u_rad, dt, self.a_m, self.n, own_accel_mps2)
                pos, vel = roe_to_lvlh(roe, u_rad, self.n)
            else:
                f = cam.focal_px
                zdot = (z - np.array([prev.p_cam_m[2] for prev in prevs])) / dt
                vel_cam = np.stack((z / f * duv[:, 0] + (c[:, 0] - cam.cx) / f * zdot,
                                    z / f * duv[:, 1] + (c[:, 1] - cam.cy) / f * zdot, zdot), axis=1)
                vel = vel_cam @ R_LVLH_FROM_CAM.T
                roe = lvlh_to_roe(pos, vel, u_rad, self.n)
            for r, (prev, m) in enumerate(zip(prevs, ms)):
                out.append(Track(prev.track_id, roe[r], pos[r], vel[r], None, prev.age + 1, prev.hits + 1, m))
                nxt.append(_Prev(prev.track_id, t_s, c[r].copy(), p_cam[m].copy(), duv[r], prev.age + 1, prev.hits + 1))
        for m in range(len(blobs)):
            if m not in used:
                nxt.append(_Prev(f"r{self._next_id}", t_s, blobs.centroid_px[m].copy(), p_cam[m].copy(), None, 0, 1))
                self._next_id += 1
        self._prev = nxt
        return out
