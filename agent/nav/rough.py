"""Paper 002 section 5's rough navigation: blobs of two successive frames -> relative state.

- Range from area: z = f sqrt(A_true / A_blob) (A_true: the face-on silhouette, 0.24 m^2);
  x, y from the pinhole relation (agent.nav.measure.rough_position_cam).
- Nearest-neighbour association between the two newest frames, on the image position predicted
  with the blob's last image velocity, gated at `gate_px`.
- Causal finite differences over the two newest frames (NOTES-002: the printed one uses the future
  frame): zdot = dz/dt, xdot = z/f * du/dt + (u - cx)/f * zdot, ydot likewise (paper sec. 5 with
  the camera axes of agent.camera.model).
- LVLH -> ROE with the paper's M (agent.roe.lvlh_to_roe).
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
from swarmhil.agent.nav.measure import rough_position_cam
from swarmhil.agent.roe import lvlh_to_roe


@dataclass
class _Prev:
    track_id: str
    t_s: float
    centroid_px: np.ndarray
    p_cam_m: np.ndarray
    image_vel_pxps: np.ndarray | None
    age: int
    hits: int


class RoughNavigator:
    name = "rough"

    def __init__(self, camera: Camera, shape: SpacecraftShape, a_m: float, n_radps: float, gate_px: float = 30.0) -> None:
        self.camera = camera
        self.area_true_m2 = float(shape.projected_areas_m2[2])
        self.a_m, self.n = a_m, n_radps
        self.gate_px = gate_px
        self._prev: list[_Prev] = []
        self._next_id = 0

    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None) -> list[Track]:
        cam = self.camera
        p_cam = rough_position_cam(blobs.centroid_px, blobs.area_px, cam, self.area_true_m2)
        pred = np.array(
            [p.centroid_px + (0.0 if p.image_vel_pxps is None else p.image_vel_pxps * (t_s - p.t_s)) for p in self._prev]
        ).reshape(-1, 2)
        cost = np.linalg.norm(pred[:, None, :] - blobs.centroid_px[None, :, :], axis=2)
        pairs = assign(cost, self.gate_px)
        out: list[Track] = []
        nxt: list[_Prev] = []
        used = set()
        if pairs:  # every pair at once: per pair the same elementwise arithmetic as one by one
            prevs = [self._prev[k] for k, _ in pairs]
            ms = [m for _, m in pairs]
            used.update(ms)
            dt = np.array([t_s - prev.t_s for prev in prevs])
            c, z = blobs.centroid_px[ms], p_cam[ms, 2]
            duv = (c - np.array([prev.centroid_px for prev in prevs])) / dt[:, None]
            zdot = (z - np.array([prev.p_cam_m[2] for prev in prevs])) / dt
            f = cam.focal_px
            vel_cam = np.stack((z / f * duv[:, 0] + (c[:, 0] - cam.cx) / f * zdot, z / f * duv[:, 1] + (c[:, 1] - cam.cy) / f * zdot, zdot), axis=1)
            # R_LVLH_FROM_CAM is a signed permutation: each row's product is exact, as R @ v of one
            pos = p_cam[ms] @ R_LVLH_FROM_CAM.T
            vel = vel_cam @ R_LVLH_FROM_CAM.T
            roe = lvlh_to_roe(pos, vel, u_rad, self.n)  # elementwise: per row as for one
            for r, (prev, m) in enumerate(zip(prevs, ms)):
                out.append(Track(prev.track_id, roe[r], pos[r], vel[r], None, prev.age + 1, prev.hits + 1, m))
                nxt.append(_Prev(prev.track_id, t_s, c[r], p_cam[m].copy(), duv[r], prev.age + 1, prev.hits + 1))
        for m in range(len(blobs)):
            if m not in used:
                nxt.append(_Prev(f"r{self._next_id}", t_s, blobs.centroid_px[m].copy(), p_cam[m].copy(), None, 0, 1))
                self._next_id += 1
        self._prev = nxt
        return out
