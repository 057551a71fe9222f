"""Navigation from rendered frames: ROE maps, association through crossings, rough navigation (issue 4).

Truth: plant.dynamics.roe_linear (the plant's model), imaged through plant.scene and the
flight renderer; the navigators see blobs only.
"""
from __future__ import annotations

import numpy as np
import pytest

from agent.blob import exact_blobs, extract_blobs
from agent.camera import Camera, Renderer, SpacecraftShape
from agent.nav import EkfNavigator, RoughNavigator, make_navigator, observation_arrays
from agent.nav.ekf import input_gamma, lvlh_to_roe_matrices, transition
from plant.dynamics import roe_linear
from plant.scene import scene

A_M = 6878137.0
N_RADPS = roe_linear.mean_motion(A_M)


def fly(roe_m, u0, dt_s, n_frames, navigator, renderer, exact=False, frame0=0, accel_obs=None):
    """Propagate neighbours (rows of roe_m, relative to the observer), image them, feed the navigator.
    Returns per frame: (truth roe (N, 6), truth pos (N, 3), truth vel (N, 3), blobs, tracks)."""
    ids = [f"sc{k}" for k in range(len(roe_m))]
    roe = np.array(roe_m, dtype=float)
    u = u0
    out = []
    own = None
    for k in range(n_frames):
        pos, vel = roe_linear.roe_to_lvlh(roe, u, N_RADPS)
        sc = scene(np.zeros(3), pos, ids)
        if exact:
            blobs = exact_blobs(sc.position_cam_m, sc.rot_body_to_cam, renderer.camera, renderer.shape)
        else:
            blobs = extract_blobs(renderer.render_rois(sc.position_cam_m, sc.rot_body_to_cam, frame=frame0 + k), renderer.detector)
        tracks = navigator.update(k * dt_s, u, blobs, own)
        out.append((roe.copy(), pos, vel, blobs, tracks))
        acc = np.zeros((len(roe), 3)) if accel_obs is None else -np.broadcast_to(accel_obs, (len(roe), 3))
        own = accel_obs
        roe = roe_linear.propagate_roe(roe, acc, u, N_RADPS, dt_s)
        u += N_RADPS * dt_s
    return out


@pytest.fixture(scope="module")
def renderer():
    return Renderer(Camera(), SpacecraftShape())


def test_flight_roe_model_agrees_with_plant():
    rng = np.random.default_rng(0)
    roe = rng.normal(0, 50, 6)
    u = 1.3
    mp, mv = lvlh_to_roe_matrices(u, N_RADPS)
    pos, vel = roe_linear.roe_to_lvlh(roe, u, N_RADPS)
    assert np.allclose(mp @ pos + mv @ vel, roe, atol=1e-9)
    dt = 10.0
    assert np.allclose(transition(N_RADPS, dt) @ roe, roe_linear.propagate_roe(roe, np.zeros(3), u, N_RADPS, dt), atol=1e-9)
    gam = input_gamma(u, A_M, N_RADPS, dt)
    ref = roe_linear.zoh_input_matrix(u, N_RADPS, dt)
    assert np.allclose(gam, ref, rtol=0, atol=(N_RADPS * dt) ** 2 / 12 * np.abs(ref).max())  # midpoint rule


def crossing_pair():
    """Two neighbours whose images cross in u at u = 0 while staying ~37 px apart in v:
    cross-track oscillations in opposite phase, small opposite radial ones."""
    return np.array([[0.0, 200.0, 4.0, 0.0, 40.0, 0.0], [0.0, 230.0, -4.0, 0.0, -40.0, 0.0]])


@pytest.mark.parametrize("kind", ["rough", "ekf"])
def test_association_keeps_identities_through_a_crossing(kind, renderer):
    cam = renderer.camera
    nav = make_navigator(kind, cam, renderer.shape, A_M, N_RADPS, {"gate_px": 30.0} if kind == "rough" else {})
    frames = fly(crossing_pair(), -0.5, 60.0, 16, nav, renderer)
    owner: dict[str, set[int]] = {}
    order_flips = set()
    min_sep_px = np.inf
    for roe, pos, vel, blobs, tracks in frames:
        uv = cam.project(pos @ np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]).T)
        order_flips.add(bool(uv[0, 0] < uv[1, 0]))
        min_sep_px = min(min_sep_px, float(np.linalg.norm(uv[0] - uv[1])))
        assert len(blobs) == 2
        for tr in tracks:
            truth = int(np.argmin(np.linalg.norm(uv - blobs.centroid_px[tr.blob_index], axis=1)))
            owner.setdefault(tr.track_id, set()).add(truth)
    assert order_flips == {True, False}  # the images did cross in u
    assert 30.0 < min_sep_px < 45.0  # ... and stayed apart by more than the rough gate
    assert len(owner) == 2 and all(len(s) == 1 for s in owner.values())
    assert {next(iter(s)) for s in owner.values()} == {0, 1}


def test_rough_navigation_with_exact_blobs_is_close_to_truth(renderer):
    """Paper 002's assumption (exact area and centroid): only the finite differences err."""
    nav = RoughNavigator(renderer.camera, renderer.shape, A_M, N_RADPS)
    roe0 = np.array([[3.0, 300.0, 10.0, -15.0, 20.0, 5.0]])
    frames = fly(roe0, 0.3, 10.0, 40, nav, renderer, exact=True)
    err_pos, err_vel = [], []
    for roe, pos, vel, blobs, tracks in frames[1:]:
        assert len(tracks) == 1
        err_pos.append(tracks[0].position_m - pos[0])
        err_vel.append(tracks[0].velocity_mps - vel[0])
    # range from the face-on area: off by the perspective of the nearer body face (~0.1 m / 300 m x 300 m)
    assert np.abs(err_pos).max() < 1.5
    # velocity: backward difference, error ~ |accel| dt / 2 ~ n^2 r dt / 2 ~ 2e-3 m/s
    assert np.abs(err_vel).max() < 5e-3


def test_rough_navigation_on_rendered_frames_is_rough(renderer):
    """With rendered images the range noise (~1-2 % at 300 m) is differenced over 10 s: the
    along-track velocity error is tens of cm/s, i.e. a*da errors of hundreds of metres."""
    nav = RoughNavigator(renderer.camera, renderer.shape, A_M, N_RADPS)
    frames = fly(np.array([[3.0, 300.0, 10.0, -15.0, 20.0, 5.0]]), 0.3, 10.0, 30, nav, renderer)
    err_da = [tracks[0].roe_m[0] - roe[0, 0] for roe, _, _, _, tracks in frames[1:]]
    assert np.sqrt(np.mean(np.square(err_da))) > 100.0


def test_tracks_feed_the_controller_observation(renderer):
    nav = EkfNavigator(renderer.camera, renderer.shape, A_M, N_RADPS)
    frames = fly(crossing_pair(), 0.2, 10.0, 6, nav, renderer)
    tracks = frames[-1][4]
    ids, pos, vel = observation_arrays(tracks)
    assert len(ids) == 2 and pos.shape == (2, 3) and vel.shape == (2, 3)
    truth_pos = frames[-1][1]
    for p in pos:
        assert np.min(np.linalg.norm(truth_pos - p, axis=1)) < 10.0


@pytest.mark.parametrize("imaging, navigator", [("exact", "rough"), ("render", "rough"), ("render", "ekf")])
def test_vision_nav_pipeline(imaging, navigator):
    from agent.nav.pipeline import VisionNav

    vn = VisionNav(A_M, N_RADPS, imaging=imaging, navigator=navigator)
    roe = np.array([[2.0, 250.0, 5.0, -5.0, 10.0, 0.0]])
    u = 0.7
    for k in range(5):
        pos, vel = roe_linear.roe_to_lvlh(roe, u, N_RADPS)
        sc = scene(np.zeros(3), pos, ["a"])
        tracks = vn.step(10.0 * k, u, sc.position_cam_m, sc.rot_body_to_cam, frame=k)
        roe = roe_linear.propagate_roe(roe, np.zeros((1, 3)), u, N_RADPS, 10.0)
        u += 10.0 * N_RADPS
    assert len(vn.last_blobs) == 1 and len(tracks) == 1
    assert np.linalg.norm(tracks[0].position_m - pos[0]) < 10.0
