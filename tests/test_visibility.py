"""plant/sensors.visibility_matrix (issue 16: written with in-place masks) gives the same matrix as
the rule as first written, on random swarms, coincident and dead spacecraft, NaN positions."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.plant.sensors import CameraGeometry, visibility_matrix


def _as_written(pos: np.ndarray, cam: CameraGeometry, alive: np.ndarray | None) -> np.ndarray:
    rel = pos[None, :, :] - pos[:, None, :]
    ahead = rel[..., 1]
    tan = cam.tan_half_fov
    vis = ((ahead > 0.0) & (np.abs(rel[..., 0]) <= tan * ahead) & (np.abs(rel[..., 2]) <= tan * ahead)
           & (np.einsum("jki,jki->jk", rel, rel) <= cam.detection_range_m**2))
    np.fill_diagonal(vis, False)
    if alive is not None:
        vis &= alive[:, None]
    return vis


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_visibility_equals_the_rule_as_written() -> None:
    rng = np.random.default_rng(16)
    cams = [CameraGeometry(), CameraGeometry(detection_range_m=150.0, image_px=640, focal_px=300.0)]
    seen = 0
    for case in range(500):
        n = int(rng.integers(0, 30))
        pos = rng.normal(scale=float(rng.choice([50.0, 300.0, 2000.0])), size=(n, 3))
        if n > 2 and case % 5 == 0:
            pos[1] = pos[0]  # coincident
            pos[2, 1] = np.nan
        if n > 5 and case % 7 == 0:  # NaN and inf across the boresight (max(|x|, |z|) <= lim keeps them out)
            pos[3, 0], pos[4, 2], pos[5, 0] = np.nan, np.inf, -np.inf
        alive = None if case % 2 else rng.random(n) < 0.8
        cam = cams[case % 2]
        got = visibility_matrix(pos, cam, alive)
        assert got.dtype == bool and np.array_equal(got, _as_written(pos, cam, alive))
        seen += int(got.sum())
    assert seen > 1000  # the cases do see each other
