"""Camera -> blobs -> navigation for one spacecraft, in one object (issue 4 scenarios).

Modes of imaging: "exact" (paper 002's assumption: exact area and centroid, no image) or
"render" (the ROI renderer with noise, then blob extraction). Navigators: "rough" or "ekf".
Input is the `scene` stimulus (agent never sees other truth): positions of the bodies in the
camera frame and their attitudes body -> camera.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from swarmhil.agent.blob.blobs import Blobs, exact_blobs, extract_blobs
from swarmhil.agent.camera.model import Camera
from swarmhil.agent.camera.render import Detector, Renderer, RoiStack
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav import make_navigator
from swarmhil.agent.nav.base import Track


class VisionNav:
    def __init__(
        self,
        a_m: float,
        n_radps: float,
        imaging: str = "render",
        navigator: str = "ekf",
        camera: Camera | None = None,
        shape: SpacecraftShape | None = None,
        detector: Detector | None = None,
        backend: str = "numpy",
        min_pixels: int = 2,
        nav_params: dict[str, Any] | None = None,
    ) -> None:
        if imaging not in ("exact", "render"):
            raise ValueError(f"unknown imaging {imaging!r}; known: exact, render")
        self.imaging = imaging
        self.renderer = Renderer(camera, shape, detector, backend=backend)
        self.min_pixels = min_pixels
        self.navigator = make_navigator(navigator, self.renderer.camera, self.renderer.shape, a_m, n_radps, nav_params)
        self.last_blobs: Blobs = Blobs.empty()
        self.last_stacks: list[RoiStack] = []

    def step(
        self,
        t_s: float,
        u_rad: float,
        pos_cam_m: np.ndarray,
        rot_body_to_cam: np.ndarray,
        frame: int,
        own_accel_mps2: np.ndarray | None = None,
    ) -> list[Track]:
        """One camera frame: image the scene, extract blobs, update the navigator."""
        blobs, stacks = self.image(pos_cam_m, rot_body_to_cam, frame)
        return self.update(t_s, u_rad, blobs, own_accel_mps2, stacks)

    def image(self, pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, frame: int) -> tuple[Blobs, list[RoiStack] | None]:
        """The imaging part of `step`: the frame's blobs, and the rendered ROI stacks (None in the exact mode)."""
        r = self.renderer
        pos = np.asarray(pos_cam_m, dtype=float).reshape(-1, 3)
        rot = np.asarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)
        if self.imaging == "exact":
            return exact_blobs(pos, rot, r.camera, r.shape), None
        stacks = r.render_rois(pos, rot, frame=frame)
        return extract_blobs(stacks, r.detector, self.min_pixels, backend=r.backend), stacks

    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None,
               stacks: list[RoiStack] | None = None) -> list[Track]:
        """The navigator's part of `step`, for a frame whose blobs are measured (the batch mode measures
        every spacecraft's exact blobs at once: agent/blob/blobs.py exact_blobs_many)."""
        self.keep(blobs, stacks)
        return self.navigator.update(t_s, u_rad, blobs, own_accel_mps2)

    def keep(self, blobs: Blobs, stacks: list[RoiStack] | None = None) -> None:
        """The frame's blobs and ROI stacks become the last ones (debug images), as `update` keeps them
        (the batch mode updates the navigators of a step together: agent/nav/ekf.py update_many)."""
        self.last_stacks = [] if stacks is None else stacks
        self.last_blobs = blobs
