"""The ROE EKF on rendered frames: error consistent with covariance (NEES), track life cycle (issue 4)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import chi2

from swarmhil.agent.blob import Blobs, extract_blobs
from swarmhil.agent.camera import Camera, Renderer, SpacecraftShape
from swarmhil.agent.nav import EkfConfig, EkfNavigator
from swarmhil.plant.dynamics import roe_linear
from swarmhil.plant.scene import scene

A_M = 6878137.0
N_RADPS = roe_linear.mean_motion(A_M)
SIGMA_ACC = 1e-6  # the neighbour's unknown acceleration, truth and filter alike


def simulated_pass(seed: int, renderer: Renderer, n_frames: int, dt_s: float = 10.0, accel_obs=None, tell_filter=True):
    """One neighbour 150-400 m ahead, random ROE, random white acceleration; rendered frames.
    Returns the per-frame (error, covariance) of the confirmed track (None before confirmation)."""
    rng = np.random.default_rng(seed)
    roe = np.array([[rng.uniform(-5, 5), rng.uniform(150, 400), *rng.uniform(-20, 20, 4)]])
    u = rng.uniform(0, 2 * np.pi)
    nav = EkfNavigator(renderer.camera, renderer.shape, A_M, N_RADPS, EkfConfig(accel_sigma_mps2=SIGMA_ACC))
    out = []
    own = None
    for k in range(n_frames):
        pos, _ = roe_linear.roe_to_lvlh(roe, u, N_RADPS)
        sc = scene(np.zeros(3), pos, ["b"])
        blobs = extract_blobs(renderer.render_rois(sc.position_cam_m, sc.rot_body_to_cam, frame=seed * 10_000 + k), renderer.detector)
        tracks = nav.update(k * dt_s, u, blobs, own if tell_filter else None)
        out.append((tracks[0].roe_m - roe[0], tracks[0].covariance_m2) if len(tracks) == 1 else None)
        acc = rng.normal(0.0, SIGMA_ACC, (1, 3))
        if accel_obs is not None:
            acc = acc - accel_obs
        own = accel_obs
        roe = roe_linear.propagate_roe(roe, acc, u, N_RADPS, dt_s)
        u += N_RADPS * dt_s
    return out


@pytest.fixture(scope="module")
def renderer():
    return Renderer(Camera(), SpacecraftShape())


def test_nees_within_chi_square_bounds(renderer):
    """Average NEES over Monte-Carlo passes (6 DOF state) within the two-sided 99 % chi-square
    interval, once the initial prior has been forgotten (frame >= 20 of 100)."""
    n_runs, n_frames, skip = 10, 100, 20
    nees = np.full((n_runs, n_frames - skip), np.nan)
    for r in range(n_runs):
        for k, item in enumerate(simulated_pass(r, renderer, n_frames)[skip:]):
            assert item is not None, "the track was lost"
            e, p = item
            nees[r, k] = e @ np.linalg.solve(p, e)
    lo, hi = chi2.ppf([0.005, 0.995], 6 * n_runs) / n_runs
    anees = nees.mean(axis=0)  # average over runs at each frame
    assert lo < nees.mean() < hi, f"mean NEES {nees.mean():.2f} outside [{lo:.2f}, {hi:.2f}]"
    assert np.mean((anees > lo) & (anees < hi)) > 0.9


def test_observer_thrust_is_accounted_for(renderer):
    accel = np.array([0.0, 2e-5, 1e-5])
    told = simulated_pass(3, renderer, 60, accel_obs=accel, tell_filter=True)
    blind = simulated_pass(3, renderer, 60, accel_obs=accel, tell_filter=False)
    e_told, p_told = told[-1]
    e_blind, _ = blind[-1]
    assert e_told @ np.linalg.solve(p_told, e_told) < chi2.ppf(0.999, 6)
    assert np.linalg.norm(e_blind) > 5 * np.linalg.norm(e_told)


def _blob_at(uv, area):
    return Blobs(np.array([uv], float), np.array([area]), np.array([0.03]), np.array([4]), np.array([[0, 0, 1, 1]]))


def test_track_creation_confirmation_gating_and_deletion():
    cam = Camera()
    nav = EkfNavigator(cam, SpacecraftShape(), A_M, N_RADPS, EkfConfig(confirm_hits=3, max_misses=2))
    area = 0.24e6 / 200.0**2  # a body 200 m dead ahead
    out = [nav.update(10.0 * k, 0.0, _blob_at((540.0, 540.0), area)) for k in range(3)]
    assert [len(t) for t in out] == [0, 0, 1]  # confirmed at the third hit
    tid = out[-1][0].track_id
    # a blob far from the prediction is gated out: it starts a new tentative track
    two = Blobs.concat([_blob_at((540.0, 540.0), area), _blob_at((900.0, 200.0), 4 * area)])
    tracks = nav.update(30.0, 0.0, two)
    assert [t.track_id for t in tracks] == [tid]
    assert len(nav.tracks) == 2
    # no blobs: the tentative track dies at once, the confirmed one coasts for max_misses frames
    assert [t.track_id for t in nav.update(40.0, 0.0, Blobs.empty())] == [tid]
    assert len(nav.tracks) == 1
    assert len(nav.update(50.0, 0.0, Blobs.empty())) == 1
    assert nav.update(60.0, 0.0, Blobs.empty()) == []
    assert nav.tracks == []


def test_output_max_misses_zero_outputs_only_the_tracks_seen_in_this_frame():
    """output_max_misses = 0: a confirmed track that misses a frame is kept (it coasts, and takes its
    blob back) but not output, so the controller acts only on neighbours the camera sees now."""
    cam = Camera()
    nav = EkfNavigator(cam, SpacecraftShape(), A_M, N_RADPS, EkfConfig(confirm_hits=3, max_misses=2, output_max_misses=0))
    area = 0.24e6 / 200.0**2
    out = [nav.update(10.0 * k, 0.0, _blob_at((540.0, 540.0), area)) for k in range(3)]
    tid = out[-1][0].track_id
    assert nav.update(30.0, 0.0, Blobs.empty()) == [] and len(nav.tracks) == 1  # kept, not output
    back = nav.update(40.0, 0.0, _blob_at((540.0, 540.0), area))
    assert [t.track_id for t in back] == [tid]  # the same track takes its blob back and is output again
    assert EkfConfig().output_max_misses == -1  # the default: as max_misses


def test_tracks_behind_the_camera_or_with_singular_s_are_not_associated_and_nothing_raises():
    from swarmhil.agent.nav.ekf import gated_distances

    nu = np.array([[[1.0, 1.0, 0.1]], [[1.0, 1.0, 0.1]], [[1.0, 1.0, 0.1]], [[0.5, -0.5, 0.0]]])
    s = np.stack([np.eye(3)[None], np.eye(3)[None], np.zeros((1, 3, 3)), 4.0 * np.eye(3)[None]])
    d2, logdet = gated_distances(nu, s, np.array([-50.0, 0.5, 200.0, 200.0]))
    assert np.isinf(d2[:3]).all()  # behind the camera, nearer than MIN_DEPTH_M, singular S
    assert d2[3, 0] == pytest.approx((0.25 + 0.25) / 4.0) and logdet[3, 0] == pytest.approx(np.log(64.0))
    # a confirmed track coasting out of view drifts behind the camera: updates go on without raising
    cam = Camera()
    nav = EkfNavigator(cam, SpacecraftShape(), A_M, N_RADPS, EkfConfig(max_coast_s=6000.0))
    area = 0.24e6 / 200.0**2
    for k in range(3):
        nav.update(10.0 * k, 0.0, _blob_at((540.0, 540.0), area))
    assert len(nav.tracks) == 1
    nav.tracks[0].xm[:, 1] = -200.0  # now 200 m behind: the prediction has depth < 0
    nav.tracks[0].combine()
    tracks = nav.update(30.0, 0.0, _blob_at((540.0, 540.0), area))
    assert len(nav.tracks) == 2  # the blob starts a new tentative track ...
    assert [(t.track_id, t.blob_index) for t in tracks] == [("e0", -1)]  # ... the coasting one is not associated
    assert all(np.isfinite(tr.p).all() for tr in nav.tracks)


# --- the two-model (IMM) filter of the shipped filter scenario -------------------------------------
# A two-model IMM as in deploy/scenarios/sabatini-20-camera-filter.toml [nav.params]: a quiet neighbour
# (1e-6 m/s^2) and a manoeuvring one (3e-5 m/s^2 here; the scenario's is 1e-4), default sojourn times
# (one orbit each)
IMM = EkfConfig(accel_sigma_mps2=1e-6, manoeuvre_accel_sigma_mps2=3e-5)
SWITCH, N_FRAMES = 60, 140  # the neighbour manoeuvres (3e-5 white) for 600 s, then is quiet (1e-6) for 800 s


def imm_pass(seed: int, renderer: Renderer, config: EkfConfig = IMM, dt_s: float = 10.0):
    """One neighbour 150-400 m ahead whose unknown acceleration is drawn from the manoeuvring model
    for SWITCH frames, then from the quiet one. Per frame: (roe error, published covariance, the
    filter's track state) of the single confirmed track, or None."""
    rng = np.random.default_rng(seed)
    roe = np.array([[rng.uniform(-5, 5), rng.uniform(150, 400), *rng.uniform(-20, 20, 4)]])
    u = rng.uniform(0, 2 * np.pi)
    nav = EkfNavigator(renderer.camera, renderer.shape, A_M, N_RADPS, config)
    out = []
    for k in range(N_FRAMES):
        pos, _ = roe_linear.roe_to_lvlh(roe, u, N_RADPS)
        sc = scene(np.zeros(3), pos, ["b"])
        blobs = extract_blobs(renderer.render_rois(sc.position_cam_m, sc.rot_body_to_cam, frame=seed * 10_000 + k), renderer.detector)
        tracks = nav.update(k * dt_s, u, blobs, None)
        ok = len(tracks) == 1 and len(nav.tracks) == 1
        snap = None
        if ok:  # the filter's state of that frame (the track object itself changes every frame)
            t = nav.tracks[0]
            snap = SimpleNamespace(x=t.x.copy(), xm=t.xm.copy(), pm=t.pm.copy(), mu=t.mu.copy())
        out.append((tracks[0].roe_m - roe[0], tracks[0].covariance_m2, snap) if ok else None)
        sigma = IMM.manoeuvre_accel_sigma_mps2 if k < SWITCH else IMM.accel_sigma_mps2
        roe = roe_linear.propagate_roe(roe, rng.normal(0.0, sigma, (1, 3)), u, N_RADPS, dt_s)
        u += N_RADPS * dt_s
    return out


def test_imm_tracks_a_manoeuvring_then_quiet_neighbour_consistently(renderer):
    """The IMM keeps the track through both regimes, follows the regime in its mode probabilities,
    publishes the moment-matched mixture, and that covariance is chi-square consistent; the quiet
    model alone loses the manoeuvring neighbour (why the scenario runs two models)."""
    n_runs = 8
    nees_man, nees_quiet_mix, nees_quiet_model, mu_man, mu_quiet = [], [], [], [], []
    for r in range(n_runs):
        frames = imm_pass(r, renderer)
        assert all(f is not None for f in frames[5:]), f"run {r}: the IMM lost the track"
        for k, (e, p, tr) in enumerate(frames[5:], start=5):
            # what is published is the mixture of the two models: x = sum mu x_m, P = sum mu (P_m + d d^T)
            d = tr.xm - tr.x
            np.testing.assert_allclose(p, np.einsum("m,mij->ij", tr.mu, tr.pm) + np.einsum("m,mi,mj->ij", tr.mu, d, d),
                                       rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(tr.x, tr.mu @ tr.xm, rtol=1e-12, atol=1e-9)
            nees = e @ np.linalg.solve(p, e)
            if 10 <= k < SWITCH:  # after the initial prior is forgotten, while manoeuvring
                nees_man.append((r, nees))
                mu_man.append(tr.mu[1])
            elif k >= SWITCH + 40:  # 400 s after the switch: the manoeuvre has left the estimate
                nees_quiet_mix.append((r, nees))
                nees_quiet_model.append((r, e @ np.linalg.solve(tr.pm[0], e)))
                mu_quiet.append(tr.mu[1])
    # mode probabilities follow the regime (measured: 0.976 while manoeuvring, 0.012 once quiet)
    assert np.mean(mu_man) > 0.9 and np.mean(mu_quiet) < 0.05, (np.mean(mu_man), np.mean(mu_quiet))

    def run_means(rows):
        a = np.array(rows)
        return np.array([a[a[:, 0] == r, 1].mean() for r in range(n_runs)])

    # frames of one run are strongly correlated: one chi^2_6 sample per run, the mean over runs in
    # the two-sided 99 % interval of chi2(6 R)/R (R = 8: [3.3, 9.6])
    lo, hi = chi2.ppf([0.005, 0.995], 6 * n_runs) / n_runs
    m = run_means(nees_man).mean()
    assert lo < m < hi, f"NEES while manoeuvring {m:.2f} outside [{lo:.2f}, {hi:.2f}] (measured 5.6)"
    m = run_means(nees_quiet_model).mean()
    assert lo < m < hi, f"quiet model's NEES once quiet {m:.2f} outside [{lo:.2f}, {hi:.2f}] (measured 4.0)"
    # the published mixture once quiet carries mu_man (~1 %) of the manoeuvring model's covariance
    # (900x the process noise): conservative by design (measured 2.9), never overconfident; below 1
    # it would be inflated ~6x beyond what the two models explain
    m = run_means(nees_quiet_mix).mean()
    assert 1.0 < m < hi, f"published NEES once quiet {m:.2f} outside [1, {hi:.2f}]"
    # one quiet model on the same manoeuvring neighbour: inconsistent, its gate drops the blob
    lost = sum(any(f is None for f in imm_pass(r, renderer, EkfConfig(accel_sigma_mps2=1e-6))[5:SWITCH])
               for r in range(4))
    assert lost >= 3, f"the single quiet filter kept {4 - lost} of 4 manoeuvring neighbours"
