"""`scene` stimulus messages (issue 4): for each observer, the poses in its camera frame of the
spacecraft near enough to matter (plant/scene.py), and its own pointing error. No other truth.

Pointing error per observer: the scenario's constant `[sensing].pointing_error_rad` plus, if
`[sensing].pointing_jitter_rad` > 0, seeded white Gaussian jitter per frame and axis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.scene import NOMINAL_BODY_TO_LVLH, SPACECRAFT_RADIUS_M, camera_from_lvlh, matrix_to_quaternion_wxyz, scene
from swarmhil.plant.sensors import TREE_MIN_COUNT, pairs_within


@dataclass(frozen=True)
class SceneBatch:
    """The scene stimuli of R observers as arrays (the batch mode, deploy/batch.py): observer r's
    bodies are rows offsets[r]:offsets[r+1], with the values its `SceneStimulus` carries (protobuf
    doubles are float64): camera-frame positions and scalar-first attitude quaternions body -> camera."""

    offsets: np.ndarray  # (R + 1,)
    neighbour: np.ndarray  # (P,) index of each body in the ids
    position_cam_m: np.ndarray  # (P, 3)
    attitude_wxyz: np.ndarray  # (P, 4)
    pointing_error_rad: np.ndarray  # (R, 3)


class SceneStimulusBuilder:
    def __init__(self, scenario: PlantConfig) -> None:
        self.ids = list(scenario.ids)
        self.max_range_m = float(scenario.camera["detection_range_m"])
        self.tan_half_fov = (scenario.camera["image_px"] / 2.0) / scenario.camera["focal_px"]
        self.bias_rad = np.asarray(scenario.sensing.get("pointing_error_rad", [0.0, 0.0, 0.0]), dtype=float)
        self.jitter_rad = float(scenario.sensing.get("pointing_jitter_rad", 0.0))
        self.rng = np.random.default_rng([int(scenario.seed), 0x5CE4E])

    def _scene(self, j: int, pos_m: np.ndarray, ids: list) -> tuple[np.ndarray, object]:
        """Observer j's pointing error (drawn here, one draw per frame) and scene; `ids` name the bodies."""
        err = self.bias_rad + (self.rng.normal(0.0, self.jitter_rad, 3) if self.jitter_rad > 0 else 0.0)
        others = np.delete(np.arange(len(self.ids)), j)
        sc = scene(pos_m[j], pos_m[others], [ids[k] for k in others], pointing_error_rad=err,
                   max_range_m=self.max_range_m, tan_half_fov=self.tan_half_fov)
        return err, sc

    def batch(self, observers: np.ndarray, pos_m: np.ndarray) -> SceneBatch:
        """`stimulus` of each of `observers` (in this order: the pointing jitter's draws), as arrays: the
        same scenes and the same quaternions (scipy's conversion is per matrix), no message."""
        if self.jitter_rad <= 0:
            return self._batch_fixed(np.asarray(observers, dtype=np.int64), pos_m)
        index = list(range(len(self.ids)))
        obs = np.asarray(observers, dtype=np.int64).tolist()
        errs, nbs, poss, rots = [], [], [], []
        counts = np.zeros(len(obs) + 1, dtype=np.int64)
        for r, j in enumerate(obs):
            err, sc = self._scene(j, pos_m, index)
            errs.append(np.broadcast_to(err, 3))
            nbs.extend(sc.ids)
            poss.append(sc.position_cam_m)
            rots.append(sc.rot_body_to_cam)
            counts[r + 1] = len(sc.ids)
        rot = np.concatenate(rots) if rots else np.zeros((0, 3, 3))
        quats = matrix_to_quaternion_wxyz(rot) if len(rot) else np.zeros((0, 4))
        return SceneBatch(np.cumsum(counts), np.array(nbs, dtype=np.int64),
                          np.concatenate(poss) if poss else np.zeros((0, 3)), quats,
                          np.array(errs, dtype=float).reshape(-1, 3))

    def _batch_fixed(self, obs: np.ndarray, pos_m: np.ndarray) -> SceneBatch:
        """`batch` without jitter: every observer's camera is turned by the same error, so `scene` of
        all of them at once (elementwise the same: each pair's difference, its row of the product
        with the one rotation, its norm and tests; the pairs in scene's order, observer by observer)."""
        n, r = len(self.ids), len(obs)
        pos = np.asarray(pos_m, dtype=float).reshape(-1, 3)
        r_cl = camera_from_lvlh(None, self.bias_rad + 0.0)  # (scene's error: bias + 0.0)
        if n >= TREE_MIN_COUNT and not np.any(self.bias_rad) and np.isfinite(pos).all():
            jj, kk, p = self._pairs_by_tree(obs, pos, r_cl)
        else:
            rel = pos[None, :, :] - pos[obs][:, None, :]  # (R, N, 3): others_pos - observer_pos, self included
            p = (rel.reshape(-1, 3) @ r_cl.T).reshape(r, n, 3)
            keep = self._in_scene(p)
            keep[np.arange(r), obs] = False  # (nobody is in its own scene)
            jj, kk = keep.nonzero()
            p = p[jj, kk]
        offsets = np.zeros(r + 1, dtype=np.int64)
        np.cumsum(np.bincount(jj, minlength=r), out=offsets[1:])
        rot = np.broadcast_to(r_cl @ NOMINAL_BODY_TO_LVLH, (len(kk), 3, 3))
        quats = matrix_to_quaternion_wxyz(rot) if len(kk) else np.zeros((0, 4))
        errs = np.broadcast_to(self.bias_rad + 0.0, (r, 3)).copy()
        return SceneBatch(offsets, kk, p, quats, errs)

    def _in_scene(self, p: np.ndarray) -> np.ndarray:
        """Which camera-frame positions p (..., 3) `scene` keeps: centre within range, in front of the
        camera, inside the FOV grown by the body's angular radius (elementwise, for any leading axes)."""
        keep = (np.linalg.norm(p, axis=-1) <= self.max_range_m) & (p[..., 2] > -SPACECRAFT_RADIUS_M)
        grow = SPACECRAFT_RADIUS_M * np.sqrt(1.0 + self.tan_half_fov**2)
        keep &= (np.abs(p[..., 0]) <= self.tan_half_fov * p[..., 2] + grow) & (np.abs(p[..., 1]) <= self.tan_half_fov * p[..., 2] + grow)
        return keep

    def _pairs_by_tree(self, obs: np.ndarray, pos: np.ndarray, r_cl: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(observer row, body index, camera-frame position) of every body in an observer's scene, in
        the (N, N) form's order, from the pairs within range of a spatial index (plant/sensors.py
        `pairs_within`; a rotation keeps distances, and the query radius is padded): each candidate's
        difference, its row of the product with the one rotation and the same tests, elementwise.
        Only for the nominal pointing (no [sensing].pointing_error_rad): its rotation is a signed
        permutation, so each row's product is exact whatever the number of rows; a general rotation's
        product is BLAS's, whose kernels (and last bits) may depend on the number of rows."""
        a, b = pairs_within(pos, self.max_range_m)
        at = np.full(len(pos), -1, dtype=np.int64)
        at[obs] = np.arange(len(obs))
        j, k = np.concatenate((a, b)), np.concatenate((b, a))
        mine = at[j] >= 0
        j, k = j[mine], k[mine]
        p = (pos[k] - pos[j]) @ r_cl.T
        keep = self._in_scene(p)
        jj, kk, p = at[j[keep]], k[keep], p[keep]
        order = np.lexsort((kk, jj))
        return jj[order], kk[order], p[order]

    def stimulus(self, j: int, pos_m: np.ndarray, u_rad: float, hdr: pb.Header) -> pb.SceneStimulus:
        err, sc = self._scene(j, pos_m, self.ids)
        msg = pb.SceneStimulus(header=hdr, u_rad=u_rad)
        e = msg.pointing_error_rad
        e.x, e.y, e.z = np.broadcast_to(err, 3).tolist()
        if sc.ids:
            quats = matrix_to_quaternion_wxyz(sc.rot_body_to_cam).tolist()
            for sid, p, q in zip(sc.ids, sc.position_cam_m.tolist(), quats):
                pose = msg.bodies.add(id=sid)
                pose.position_cam_m.x, pose.position_cam_m.y, pose.position_cam_m.z = p
                a = pose.attitude_cam
                a.w, a.x, a.y, a.z = q
        return msg
