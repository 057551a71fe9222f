"""`scene` stimulus messages (issue 4): for each observer, the poses in its camera frame of the
spacecraft near enough to matter (plant/scene.py), and its own pointing error. No other truth.

Pointing error per observer: the scenario's constant `[sensing].pointing_error_rad` plus, if
`[sensing].pointing_jitter_rad` > 0, seeded white Gaussian jitter per frame and axis.
"""
from __future__ import annotations


import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.scene import matrix_to_quaternion_wxyz, scene


class SceneStimulusBuilder:
    def __init__(self, scenario: PlantConfig) -> None:
        self.ids = list(scenario.ids)
        self.max_range_m = float(scenario.camera["detection_range_m"])
        self.tan_half_fov = (scenario.camera["image_px"] / 2.0) / scenario.camera["focal_px"]
        self.bias_rad = np.asarray(scenario.sensing.get("pointing_error_rad", [0.0, 0.0, 0.0]), dtype=float)
        self.jitter_rad = float(scenario.sensing.get("pointing_jitter_rad", 0.0))
        self.rng = np.random.default_rng([int(scenario.seed), 0x5CE4E])

    def stimulus(self, j: int, pos_m: np.ndarray, u_rad: float, hdr: pb.Header) -> pb.SceneStimulus:
        err = self.bias_rad + (self.rng.normal(0.0, self.jitter_rad, 3) if self.jitter_rad > 0 else 0.0)
        others = np.delete(np.arange(len(self.ids)), j)
        sc = scene(pos_m[j], pos_m[others], [self.ids[k] for k in others], pointing_error_rad=err,
                   max_range_m=self.max_range_m, tan_half_fov=self.tan_half_fov)
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
