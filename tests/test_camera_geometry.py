"""Camera projection and field-of-view geometry against hand-computed cases (issue 4)."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.agent.camera import R_CAM_FROM_LVLH, Camera, quat_to_matrix
from swarmhil.plant import scene as plant_scene


def test_camera_frame_is_a_rotation_with_boresight_along_track():
    assert np.allclose(R_CAM_FROM_LVLH @ R_CAM_FROM_LVLH.T, np.eye(3))
    assert np.linalg.det(R_CAM_FROM_LVLH) == pytest.approx(1.0)
    assert np.allclose(R_CAM_FROM_LVLH @ [0, 1, 0], [0, 0, 1])  # +y LVLH (along-track) -> boresight
    assert np.allclose(R_CAM_FROM_LVLH @ [-1, 0, 0], [0, 1, 0])  # nadir -> image down
    assert np.allclose(plant_scene.R_CAM_FROM_LVLH, R_CAM_FROM_LVLH)  # plant and flight copies agree


@pytest.mark.parametrize(
    "p_cam, uv",
    [
        ((0.0, 0.0, 10.0), (540.0, 540.0)),
        ((1.0, 0.0, 10.0), (640.0, 540.0)),
        ((-2.0, 1.0, 4.0), (40.0, 790.0)),
        ((27.0, -27.0, 50.0), (1080.0, 0.0)),
    ],
)
def test_pinhole_projection_hand_cases(p_cam, uv):
    cam = Camera()
    assert np.allclose(cam.project(np.array(p_cam)), uv, atol=1e-12)
    assert np.allclose(cam.ray(np.array(uv)) * p_cam[2], p_cam, atol=1e-12)


def test_paper_relation_in_lvlh():
    """Paper 002 sec. 5: p_x = f x/y, p_y = f z/y; here u = cx - f z/y, v = cy - f x/y."""
    cam = Camera()
    rel_lvlh = np.array([10.0, 100.0, 5.0])
    u, v = cam.project(R_CAM_FROM_LVLH @ rel_lvlh)
    assert u == pytest.approx(540.0 - 1000.0 * 5.0 / 100.0)
    assert v == pytest.approx(540.0 - 1000.0 * 10.0 / 100.0)


def test_field_of_view_edges():
    cam = Camera()
    assert np.degrees(cam.half_fov_rad[0]) == pytest.approx(28.369, abs=1e-3)  # atan(0.54)
    z = 200.0
    edge = 0.54 * z
    pts = np.array(
        [
            [edge - 1e-6, 0, z],  # just inside the right edge
            [edge + 1e-3, 0, z],  # just outside
            [0, -edge + 1e-6, z],  # just inside the top edge
            [0, -edge - 1e-3, z],
            [0, 0, -z],  # behind the camera
            [edge - 1e-6, edge - 1e-6, z],  # the square FOV includes its corners (39.1 deg off-axis)
        ]
    )
    assert cam.in_fov(pts).tolist() == [True, False, True, False, False, True]


def test_scene_range_fov_and_frames():
    obs = np.array([5.0, -3.0, 2.0])
    rel = np.array(
        [
            [0.0, 100.0, 0.0],  # dead ahead
            [20.0, 300.0, -40.0],  # ahead, off-axis
            [0.0, -100.0, 0.0],  # behind
            [0.0, 499.0, 0.0],  # within range
            [0.0, 501.0, 0.0],  # beyond 500 m
            [200.0, 100.0, 0.0],  # outside the field of view
        ]
    )
    ids = ["a", "b", "c", "d", "e", "f"]
    sc = plant_scene.scene(obs, obs + rel, ids)
    assert sc.ids == ["a", "b", "d"]
    assert np.allclose(sc.position_cam_m[1], [40.0, -20.0, 300.0])  # (-z, -x, y)
    assert np.allclose(sc.rot_body_to_cam, np.eye(3))  # nominal bodies seen by a nominal camera


def test_scene_pointing_error_shifts_the_image():
    """A camera turned by theta about its y (down) axis looks right: a target dead ahead moves left by f tan(theta)."""
    cam = Camera()
    theta = 0.01
    sc = plant_scene.scene(np.zeros(3), np.array([[0.0, 200.0, 0.0]]), ["a"], pointing_error_rad=np.array([0.0, theta, 0.0]))
    u, v = cam.project(sc.position_cam_m[0])
    assert u == pytest.approx(540.0 - 1000.0 * np.tan(theta), abs=1e-9)
    assert v == pytest.approx(540.0, abs=1e-9)
    r = sc.rot_body_to_cam[0]
    assert np.allclose(r @ [0, 0, 1], [-np.sin(theta), 0, np.cos(theta)])


def test_quaternion_wire_round_trip():
    rng = np.random.default_rng(3)
    from scipy.spatial.transform import Rotation

    rot = Rotation.random(5, random_state=rng).as_matrix()
    q = plant_scene.matrix_to_quaternion_wxyz(rot)
    assert np.allclose(quat_to_matrix(q), rot)
