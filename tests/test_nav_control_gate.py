"""Which tracks the controller acts on (agent/perception.py control_tracks, [nav] control_max_sigma_m and
control_sigma_model) and the IMM quiet model's covariance the EKF outputs for it (agent/nav/ekf.py)."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.agent.camera.model import Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav.base import Track
from swarmhil.agent.nav.ekf import EkfConfig, EkfNavigator, tracks_out
from swarmhil.agent.perception import control_tracks, nav_config

N_RADPS = 0.0011067834463349404
A_M = 6878137.0


def _track(tid: str, mixture_sigma_m: float, quiet_sigma_m: float | None) -> Track:
    quiet = None if quiet_sigma_m is None else np.eye(6) * quiet_sigma_m**2
    return Track(tid, np.zeros(6), np.array([0.0, 300.0, 0.0]), np.zeros(3), np.eye(6) * mixture_sigma_m**2,
                 quiet_covariance_m2=quiet)


def test_the_gate_reads_the_covariance_of_the_chosen_model():
    tracks = [_track("a", 30.0, 4.0), _track("b", 5.0, 3.0), _track("c", 30.0, None), _track("d", 30.0, 12.0)]
    assert [t.track_id for t in control_tracks(tracks, 10.0)] == ["b"]
    assert [t.track_id for t in control_tracks(tracks, 10.0, "mixture")] == ["b"]
    # the quiet model's covariance where a track has one, the track's own otherwise
    assert [t.track_id for t in control_tracks(tracks, 10.0, "quiet")] == ["a", "b"]
    assert len(control_tracks(tracks, 0.0, "quiet")) == 4  # no gate


def test_the_gate_ignores_a_dl_which_has_no_gain():
    t = _track("a", 1.0, 1.0)
    t.covariance_m2[1, 1] = 1e6
    t.quiet_covariance_m2[1, 1] = 1e6
    assert control_tracks([t], 10.0, "mixture") == [t] == control_tracks([t], 10.0, "quiet")


def test_nav_config_rejects_an_unknown_gate_model():
    assert nav_config({"control_sigma_model": "quiet"})["control_sigma_model"] == "quiet"
    assert nav_config({})["control_sigma_model"] == "mixture"
    with pytest.raises(ValueError, match=r"\[nav\]\.control_sigma_model must be 'mixture' or 'quiet'"):
        nav_config({"control_sigma_model": "quietest"})


def _navigator(**cfg) -> EkfNavigator:
    return EkfNavigator(Camera(), SpacecraftShape(), A_M, N_RADPS, EkfConfig(**cfg))


def test_the_output_track_carries_the_imm_quiet_model_covariance():
    """With the IMM the quiet model's covariance (xm[0], pm[0]) goes out beside the mixture's; after a
    manoeuvring neighbour's frames the two differ, and the quiet one is the smaller in a*da."""
    cam = Camera()
    centroid = np.array([cam.cx + 300.0, cam.cy - 200.0])
    nav = _navigator(manoeuvre_accel_sigma_mps2=1e-4)
    track = nav._new_track(0.0, centroid, 1.0, 0.05)
    nav.tracks = [track]
    nav._t, nav._u = 0.0, 0.0
    for k in range(1, 30):  # predictions only: the manoeuvring model's spread grows, the quiet one's hardly
        nav._predict(10.0, nav._u, None)
        nav._t, nav._u = 10.0 * k, nav._u + 10.0 * N_RADPS
    (out,) = tracks_out([[track]], nav._u, N_RADPS)
    np.testing.assert_array_equal(out[0].quiet_covariance_m2, track.pm[0])
    np.testing.assert_array_equal(out[0].covariance_m2, track.p)
    assert out[0].quiet_covariance_m2[0, 0] < out[0].covariance_m2[0, 0]
    single = _navigator()._new_track(0.0, centroid, 1.0, 0.05)
    (out,) = tracks_out([[single]], 0.0, N_RADPS)
    assert out[0].quiet_covariance_m2 is None
