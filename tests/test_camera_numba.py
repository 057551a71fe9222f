"""The compiled backend (numba) renders and labels exactly what the numpy reference does.

Every shipped camera scenario runs the numba backend (`backend = "auto"`), so the default suite
compares it with the numpy reference on small images (a few scenes at 160 x 120 px); the long
sweep (12 scenes of 8 bodies at 320 x 240 px) is marked `system`. The kernels are compiled once
and cached on disk (njit(cache=True)); a cold cache costs ~25 s of CPU, paid by the first test
that renders with numba (the shipped filter scenario in tests/test_navreport.py does too)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarmhil.agent.blob import extract_blobs
from swarmhil.agent.camera import Camera, Renderer
from system_tools import require_module


@pytest.fixture(autouse=True)
def _numba() -> None:
    require_module("numba")  # an extra of `make setup`: a failure in CI, a skip with the command elsewhere


def scenes(rng, count, n):
    for k in range(count):
        z = rng.uniform(2.0, 150.0, n)
        pos = np.stack((rng.uniform(-0.6, 0.6, n) * z, rng.uniform(-0.6, 0.6, n) * z, z), 1)
        pos[1] = pos[0] + rng.normal(0, [0.5, 0.1, 1.0])  # a near pair: merged canvases
        pos[2, 2] = -5.0  # one behind the camera
        rot = np.where(rng.uniform(size=(n, 1, 1)) < 0.5, np.eye(3), Rotation.random(n, random_state=k).as_matrix())
        yield k, pos, rot


def _compare(cam: Camera, rng, count: int, n: int) -> int:
    """Render and label `count` scenes of n bodies with both backends; returns the blobs compared."""
    ref, fast = Renderer(cam, backend="numpy"), Renderer(cam, backend="numba")
    assert ref.backend == "numpy" and fast.backend == "numba"
    compared = 0
    for k, pos, rot in scenes(rng, count, n):
        a, b = ref.render_rois(pos, rot, frame=k), fast.render_rois(pos, rot, frame=k)
        assert len(a) == len(b)
        if not a:
            continue
        # canvases may come in another order: compare by origin
        oa = {tuple(o): g for g, o in enumerate(a[0].origin_px)}
        assert sorted(oa) == sorted(tuple(o) for o in b[0].origin_px)
        for gb, o in enumerate(b[0].origin_px):
            ga = oa[tuple(o)]
            h, w = a[0].size_px[ga]
            # same equations in float64, summed in another order: electrons agree to round-off
            assert np.allclose(a[0].image_e[ga, :h, :w], b[0].image_e[gb, :h, :w], atol=1e-6)
        for backend in ("numpy", "numba"):
            ba = extract_blobs(a, ref.detector, backend="numpy")
            bb = extract_blobs(b, fast.detector, backend=backend)
            assert np.array_equal(ba.n_pixels, bb.n_pixels) and np.array_equal(ba.bbox_px, bb.bbox_px)
            assert np.allclose(ba.centroid_px, bb.centroid_px, atol=1e-9)
            assert np.allclose(ba.area_px, bb.area_px, atol=1e-9)
            assert np.allclose(ba.area_sigma_px, bb.area_sigma_px, atol=1e-12)
            compared += len(ba)
        assert np.allclose(ref.render_full(pos, rot, frame=k), fast.render_full(pos, rot, frame=k), atol=1e-6)
    return compared


def test_numba_backend_equals_numpy_backend_small_images():
    """Default suite: 4 scenes of 5 bodies (a merged near pair, one behind the camera) at 160 x 120 px."""
    cam = Camera(width_px=160, height_px=120, focal_px=150.0)
    assert _compare(cam, np.random.default_rng(5), 4, 5) > 0


@pytest.mark.system
def test_numba_backend_equals_numpy_backend():
    cam = Camera(width_px=320, height_px=240, focal_px=300.0)
    assert _compare(cam, np.random.default_rng(2), 12, 8) > 0
