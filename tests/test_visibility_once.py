"""The camera visibility rule and the weak-component count, written once in plant/sensors.py (issue
25: each was written three times, in the plant, the reports and the viewer; this test compared the
three before they were merged), give, as the plant, the reports and the viewer call them, the values
of the rule and the count written plainly here (pair by pair; scipy's connected_components), on random geometry with the
cases at the edges: on the field-of-view boundary, at the detection range, coincident, behind the
camera, dead observers and dead targets, NaN and inf positions, the paper's and another camera."""
from __future__ import annotations

import math

import numpy as np
import pytest

from swarmhil.plant.sensors import CameraGeometry, visibility_matrix, visibility_series, weak_components, weakly_connected

CAMS = [CameraGeometry(), CameraGeometry(detection_range_m=150.0, image_px=640, focal_px=300.0)]


def _pairwise(pos: np.ndarray, cam: CameraGeometry, alive: np.ndarray | None) -> np.ndarray:
    """The rule pair by pair (paper 002 sec. 3.1, 5): j sees k when rel = r_k - r_j has rel_y > 0,
    |rel_x| <= tan * rel_y, |rel_z| <= tan * rel_y and |rel|^2 <= range^2; nobody sees itself, a
    dead observer sees nothing, a dead target is still seen."""
    n = len(pos)
    tan, r2 = cam.tan_half_fov, cam.detection_range_m ** 2
    out = np.zeros((n, n), dtype=bool)
    for j in range(n):
        for k in range(n):
            x, y, z = (float(c) for c in pos[k] - pos[j])
            out[j, k] = (j != k and (alive is None or bool(alive[j])) and y > 0.0 and abs(x) <= tan * y
                         and abs(z) <= tan * y and x * x + y * y + z * z <= r2)
    return out


def _geometry(rng: np.random.Generator, case: int, cam: CameraGeometry) -> np.ndarray:
    n = int(rng.integers(1, 14))
    pos = rng.normal(scale=float(rng.choice([50.0, 300.0, 2000.0])), size=(n, 3))
    if n >= 6:
        pos[0] = 0.0                                         # an observer at the origin: rel = r_k exactly
        y = float(rng.uniform(1.0, 100.0))
        pos[1] = [cam.tan_half_fov * y, y, 0.0]              # on the FOV's x edge
        pos[2] = [0.0, y, -cam.tan_half_fov * y]             # on the FOV's z edge
        pos[3] = [0.0, cam.detection_range_m, 0.0]           # at the detection range
        pos[4] = pos[5] if case % 3 else [0.0, -y, 0.0]      # coincident, or behind
    if n >= 9 and case % 4 == 0:
        pos[6, 0], pos[7, 2], pos[8, 1] = np.nan, np.inf, -np.inf
    return pos


def _weak_count(vis: np.ndarray, nodes: np.ndarray) -> int:
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(nodes)
    return connected_components(vis[np.ix_(idx, idx)], directed=True, connection="weak")[0] if len(idx) else 0


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_the_plant_the_reports_and_the_viewer_see_the_same_and_count_the_same() -> None:
    pytest.importorskip("rerun")
    from swarmhil.dashboards.rerun_bridge import CameraRule

    rng = np.random.default_rng(25)
    edges = 0
    for case in range(300):
        cam = CAMS[case % 2]
        rule = CameraRule(cam.detection_range_m, cam.tan_half_fov)
        steps = [_geometry(rng, case, cam) for _ in range(3)]
        n = min(len(p) for p in steps)
        pos = np.stack([p[:n] for p in steps])                       # (3, n, 3)
        alive = rng.random((3, n)) < (1.0 if case % 2 else 0.7)
        want = np.stack([_pairwise(pos[t], cam, alive[t]) for t in range(3)])
        edges += int(want[:, 0, 1:4].sum())
        for t in range(3):
            assert np.array_equal(visibility_matrix(pos[t], cam, alive[t]), want[t])   # the plant, per step
        assert np.array_equal(visibility_series(pos, cam, alive), want)                # the reports
        assert np.array_equal(visibility_series(pos, rule, alive), want)               # the viewer's CameraRule
        # components: the reports count every node (a dead one is still seen), the viewer the alive ones
        all_nodes = np.ones(n, dtype=bool)
        assert weak_components(want)[0].tolist() == [_weak_count(want[t], all_nodes) for t in range(3)]
        n_alive, labels = weak_components(want, alive)
        assert n_alive.tolist() == [_weak_count(want[t], alive[t]) for t in range(3)]
        assert np.all((labels >= 0) == alive) and all(len(set(labels[t][alive[t]])) == n_alive[t] for t in range(3))
        for t in range(3):
            assert weakly_connected(want[t]) == (_weak_count(want[t], all_nodes) == 1)
    assert edges > 100  # the edge cases (FOV boundary, range) are seen, not only missed
    assert math.isclose(CAMS[0].tan_half_fov, 0.54)
