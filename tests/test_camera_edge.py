"""Regression: a body in the scene (within the FOV grown by its size) whose silhouette covers no
pixel row of the frame must render to an empty, float image, not crash the flight software.
It crashed a 24 h rendered run (np.bincount of an empty input is int64)."""
from __future__ import annotations

import numpy as np

from agent.camera.render import Renderer


def test_bodies_at_the_edge_of_the_field_of_view_render_without_error() -> None:
    r = Renderer()
    rng = np.random.default_rng(1)
    for _ in range(3000):
        z = rng.uniform(1, 500)
        x = rng.uniform(0.5, 0.6) * z * rng.choice([-1, 1])
        y = rng.uniform(-0.6, 0.6) * z
        stacks = r.render_rois(np.array([[x, y, z]]), np.eye(3)[None], frame=1)
        for st in stacks:
            assert st.image_e.dtype == np.float64 and np.all(np.isfinite(st.image_e))
    # the case that crashed
    stacks = r.render_rois(np.array([[219.7755584987305, -231.3723273737407, 426.63715762635417]]), np.eye(3)[None], frame=1)
    assert all(st.image_e.dtype == np.float64 for st in stacks)
