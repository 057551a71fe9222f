"""Blob extraction in ROIs against full-frame labelling with scipy.ndimage (issue 4)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation

from swarmhil.agent.blob import exact_blobs, extract_blobs, extract_blobs_full
from swarmhil.agent.camera import Camera, Detector, Renderer, SpacecraftShape


def reference_blobs(image: np.ndarray, det: Detector, min_pixels: int):
    """scipy.ndimage.label over the whole frame; photometry over bbox + 1 px, computed directly."""
    labels, n = ndimage.label(image > det.threshold_e, structure=np.ones((3, 3)))
    out = []
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        npx = int(np.sum(labels[sl] == k))
        if npx < min_pixels:
            continue
        r0, r1 = max(sl[0].start - 1, 0), min(sl[0].stop + 1, image.shape[0])
        c0, c1 = max(sl[1].start - 1, 0), min(sl[1].stop + 1, image.shape[1])
        ap = image[r0:r1, c0:c1]
        rr, cc = np.mgrid[r0:r1, c0:c1] + 0.5
        flux = ap.sum()
        out.append((npx, (sl[0].start, sl[1].start, sl[0].stop, sl[1].stop), (np.sum(ap * cc) / flux, np.sum(ap * rr) / flux), flux / det.signal_e))
    out.sort(key=lambda b: (b[2][1], b[2][0]))
    return out


def random_scene(rng, n, z_range, spread=0.55):
    z = rng.uniform(*z_range, n)
    pos = np.stack((rng.uniform(-spread, spread, n) * z, rng.uniform(-spread, spread, n) * z, z), 1)
    k = n // 3
    pos[1 : 1 + k] = pos[1 : 1 + k] * 0 + pos[0] + rng.normal(0, [0.6, 0.15, 2.0], (k, 3))  # near pairs: merges
    rot = np.where(rng.uniform(size=(n, 1, 1)) < 0.5, np.eye(3), Rotation.random(n, random_state=rng).as_matrix())
    return pos, rot


def test_roi_labelling_equals_full_frame_labelling_on_random_scenes():
    cam = Camera(width_px=320, height_px=240, focal_px=300.0)
    rend = Renderer(cam)
    det = rend.detector
    rng = np.random.default_rng(5)
    n_merged = 0
    for frame in range(8):
        pos, rot = random_scene(rng, 9, (4.0, 120.0))
        stacks = rend.render_rois(pos, rot, frame=frame)
        n_merged += sum(len(m) > 1 for st in stacks for m in st.members)
        mine = extract_blobs(stacks, det, min_pixels=2)
        full = rend.render_full(pos, rot, frame=frame)
        ref = reference_blobs(full, det, min_pixels=2)
        assert len(mine) == len(ref)
        for k, (npx, bbox, centroid, area) in enumerate(ref):
            assert mine.n_pixels[k] == npx
            assert tuple(mine.bbox_px[k]) == bbox
            assert np.allclose(mine.centroid_px[k], centroid, atol=1e-6)
            assert mine.area_px[k] == pytest.approx(area, rel=1e-6, abs=1e-6)
        # the full-frame path of the flight code agrees too
        fb = extract_blobs_full(full, det, min_pixels=2)
        assert np.allclose(fb.centroid_px, mine.centroid_px, atol=1e-6)
    assert n_merged > 0  # the scenes did exercise merged canvases


def test_minimum_size_and_connectivity():
    det = Detector()
    img = np.zeros((1, 12, 12))
    img[0, 2, 2] = 500.0  # a single pixel: below min_pixels = 2
    img[0, 6, 6] = img[0, 7, 7] = 500.0  # diagonal neighbours: one 8-connected blob
    img[0, 6, 9] = img[0, 6, 10] = 30.0  # below threshold
    from swarmhil.agent.blob import blobs_in_stack

    b = blobs_in_stack(img, np.array([[100, 200]]), np.array([[12, 12]]), det, min_pixels=2)
    assert len(b) == 1
    assert b.n_pixels[0] == 2
    assert tuple(b.bbox_px[0]) == (106, 206, 108, 208)
    # aperture = rows 105..108, cols 205..208: the two bright pixels (and no others)
    assert np.allclose(b.centroid_px[0], [207.0, 107.0])
    assert b.area_px[0] == pytest.approx(1000.0 / det.signal_e)
    assert len(blobs_in_stack(img, np.array([[0, 0]]), np.array([[12, 12]]), det, min_pixels=1)) == 2


def test_merging_of_overlapping_bodies():
    cam = Camera()
    rend = Renderer(cam)
    pos = np.array([[0.0, 0.0, 50.0], [0.9, 0.05, 52.0], [10.0, 0.0, 50.0]])
    stacks = rend.render_rois(pos, np.broadcast_to(np.eye(3), (3, 3, 3)), frame=1)
    blobs = extract_blobs(stacks, rend.detector)
    assert len(blobs) == 2  # the first two touch in the image: one blob


def test_exact_blobs_are_the_papers_assumption():
    cam = Camera()
    shape = SpacecraftShape()
    pos = np.array([[0.0, 0.0, 100.0], [30.0, -10.0, 200.0], [0.0, 0.0, -10.0]])
    b = exact_blobs(pos, np.broadcast_to(np.eye(3), (3, 3, 3)), cam, shape)
    assert len(b) == 2
    assert np.allclose(b.centroid_px, cam.project(pos[[1, 0]]))
    assert b.area_px[1] == pytest.approx(0.24e6 / 100.0**2, rel=2e-3)
