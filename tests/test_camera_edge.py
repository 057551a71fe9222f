"""Regression: a body in the scene (within the FOV grown by its size) whose silhouette covers no
pixel row of the frame must render to an empty, float image, not crash the flight software.
It crashed a 24 h rendered run (np.bincount of an empty input is int64).

And what the edge renders is right: with noise off an image holds signal_e x the covered area of
each pixel, so the electrons summed over the frame are the silhouette's area inside the frame.
That is checked against a camera three times as wide and high with the same focal length (the
frame is its central window, cx = W/2): the big camera sees the whole silhouette, whose summed
coverage must equal the exact shoelace area (silhouette_area_px), and the clipped frame must hold
exactly the big render's central window."""
from __future__ import annotations

import numpy as np

from swarmhil.agent.camera import Camera
from swarmhil.agent.camera.render import Renderer, silhouette_area_px


def _edge_positions(rng: np.random.Generator, n: int):
    for _ in range(n):
        z = rng.uniform(1, 500)
        x = rng.uniform(0.5, 0.6) * z * rng.choice([-1, 1])  # around the frame's left/right edge (tan = 0.54)
        y = rng.uniform(-0.6, 0.6) * z
        yield np.array([[x, y, z]])


def test_bodies_at_the_edge_of_the_field_of_view_render_without_error() -> None:
    r = Renderer()
    rng = np.random.default_rng(1)
    for pos in _edge_positions(rng, 3000):
        stacks = r.render_rois(pos, np.eye(3)[None], frame=1)
        for st in stacks:
            assert st.image_e.dtype == np.float64 and np.all(np.isfinite(st.image_e))
    # the case that crashed
    stacks = r.render_rois(np.array([[219.7755584987305, -231.3723273737407, 426.63715762635417]]), np.eye(3)[None], frame=1)
    assert all(st.image_e.dtype == np.float64 for st in stacks)


def _covered_px(stacks, signal_e: float, window=None) -> float:
    """Covered area [px^2] in the ROI canvases (noise off), optionally only inside window ((r0, r1), (c0, c1))."""
    total = 0.0
    for st in stacks:
        for g, ((r0, c0), (h, w)) in enumerate(zip(st.origin_px, st.size_px)):
            img = st.image_e[g, :h, :w]
            if window is not None:
                (R0, R1), (C0, C1) = window
                a0, a1, b0, b1 = max(R0 - r0, 0), min(R1 - r0, h), max(C0 - c0, 0), min(C1 - c0, w)
                img = img[a0:a1, b0:b1] if a1 > a0 and b1 > b0 else img[:0, :0]
            total += float(img.sum())
    return total / signal_e


def test_bodies_at_the_edge_render_their_silhouette_area_inside_the_frame() -> None:
    r = Renderer()
    cam = r.camera
    W, H = cam.width_px, cam.height_px
    big = Renderer(Camera(width_px=3 * W, height_px=3 * H, focal_px=cam.focal_px, max_range_m=cam.max_range_m),
                   r.shape, r.detector)
    rng = np.random.default_rng(1)
    seen = clipped = 0
    for pos in _edge_positions(rng, 300):
        rot = np.eye(3)[None]
        in_frame = _covered_px(r.render_rois(pos, rot, frame=1, noise=False), r.detector.signal_e)
        stacks = big.render_rois(pos, rot, frame=1, noise=False)
        whole = _covered_px(stacks, r.detector.signal_e)
        window = _covered_px(stacks, r.detector.signal_e, ((H, 2 * H), (W, 2 * W)))
        exact = float(silhouette_area_px(pos, rot, big.camera, big.shape)[0])
        # exact-area rasterization: the per-pixel coverages sum to the polygon area up to float64
        # round-off over ~1e4 pixels of a near body (measured 1.1e-9 relative); 1e-8 relative
        assert abs(whole - exact) <= 1e-6 + 1e-8 * exact, (pos, whole, exact)
        # clipping at the frame edge neither drops nor adds coverage (measured 9e-12 px^2)
        assert abs(in_frame - window) <= 1e-6 + 1e-9 * exact, (pos, in_frame, window)
        assert in_frame <= exact + 1e-6
        seen += in_frame > 0
        clipped += 0 < in_frame < 0.999 * exact
    # the sample really exercises the edge: 113 of 300 cover frame pixels, 33 of them cut by the edge
    assert seen > 80 and clipped > 20, (seen, clipped)
