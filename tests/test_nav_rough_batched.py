"""The rough navigators of a batch step updated together (agent/nav/rough.py `update_many`) end in
the state each one's own `update` gives and output the same tracks, bit for bit: on every frame of
a batch run of the paper's exact-blob scenario, on synthetic swarms under every setting of the
navigator, and when a fault hits the batch's arithmetic or one navigator's part of it."""
from __future__ import annotations

import copy

import numpy as np
import pytest
from conftest import ROOT, checked_against_own_updates

from swarmhil.agent.blob.blobs import Blobs, exact_blobs
from swarmhil.agent.camera.model import R_CAM_FROM_LVLH, Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav import rough
from swarmhil.agent.nav.rough import RoughNavigator, pair_costs, update_many
from swarmhil.agent.roe import roe_to_lvlh

A_M, N_RADPS = 6878137.0, 0.0011068  # 500 km circular


def _nav_state(nav: RoughNavigator) -> tuple:
    """Everything of a RoughNavigator that the next frame reads, as comparable values."""
    st = nav.state
    return (tuple(st.ids), *(getattr(st, f).dtype.str + getattr(st, f).tobytes().hex() for f in st.ARRAYS),
            nav._next_id)


def _tracks_bytes(tracks) -> list[tuple]:
    return [(t.track_id, t.age_steps, t.hits, t.blob_index, t.covariance_m2,
             *(np.asarray(getattr(t, f)).tobytes() for f in ("roe_m", "position_m", "velocity_mps"))) for t in tracks]


def _frames(rng: np.random.Generator, counts: list[int], frames: int, camera: Camera, shape: SpacecraftShape):
    """Per frame: (t, u, each observer's exact blobs, each observer's own acceleration or None) of
    neighbours on relative orbits drifting along-track (in and out of the 500 m view), now and then
    an empty frame (a missed one: every track dropped)."""
    roes = [np.column_stack((rng.normal(0.0, 20.0, k), rng.uniform(30.0, 470.0, k), *rng.normal(0.0, 40.0, (4, k))))
            for k in counts]
    for f in range(frames):
        u, blobs, acc = N_RADPS * 10.0 * f, [], []
        for roe in roes:
            roe[:, 1] -= 1.5 * N_RADPS * roe[:, 0] * 10.0
            pos, _ = roe_to_lvlh(roe, u, N_RADPS)
            b = exact_blobs(pos @ R_CAM_FROM_LVLH.T, np.repeat(np.eye(3)[None], len(roe), 0), camera, shape)
            blobs.append(Blobs.empty() if rng.random() < 0.04 else b)
            acc.append(rng.normal(0.0, 3e-4, 3) if rng.random() < 0.7 else None)
        yield 10.0 * f, u, blobs, acc


@pytest.mark.parametrize("params", [{}, {"velocity": "difference"}, {"range_model": "face_on"},
                                    {"range_model": "face_on", "velocity": "difference", "gate_px": 12.0}],
                         ids=["silhouette-dynamics", "silhouette-difference", "face_on-dynamics", "face_on-difference-gate12"])
def test_all_observers_together_equal_each_observers_own_update(params: dict) -> None:
    """Seven observers of 1 to 14 neighbours each, 150 frames: after every frame each navigator's
    tracks (ids, times, centroids, positions, image velocities, ages, hits) and next id, and every
    output track, are those of a copy that ran its own `update` on the same blobs and acceleration."""
    camera, shape = Camera(), SpacecraftShape()
    rng = np.random.default_rng(len(params))
    navs = [RoughNavigator(camera, shape, A_M, N_RADPS, **params) for _ in range(7)]
    seen = {"outputs": 0, "born": 0, "dropped": 0}
    for t, u, blobs, acc in _frames(rng, [1, 3, 5, 8, 14, 2, 6], 150, camera, shape):
        own = [copy.deepcopy(nav) for nav in navs]
        expect = [nav.update(t, u, b, a) for nav, b, a in zip(own, blobs, acc)]
        before = [(len(nav.state), nav._next_id) for nav in navs]
        got = update_many(navs, t, u, blobs, acc)
        for nav, mine, out, want, (n0, k0) in zip(navs, own, got, expect, before):
            assert not isinstance(out, Exception)
            assert _nav_state(nav) == _nav_state(mine), t
            assert _tracks_bytes(out) == _tracks_bytes(want), t
            seen["outputs"] += len(out)
            seen["born"] += nav._next_id - k0
            seen["dropped"] += n0 - len(out)
    # real work: many estimates, tracks born and dropped (empty frames, neighbours leaving the view, gating)
    assert seen["outputs"] > 3000 and seen["born"] > 100 and seen["dropped"] > 100, seen


def test_all_observers_together_equal_each_observers_own_update_on_a_batch_run(tmp_path, monkeypatch) -> None:
    """sabatini-20-camera-exact in batch mode (the paper's exact blobs, the rough navigator), 600 s: at
    every frame, a copy of each of the 20 navigators runs its own `update` on the blobs and own
    acceleration the batch hands `update_many`; afterwards every navigator's tracks and every output
    track are the same bytes."""
    from swarmhil.agent import perception
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    seen = {"frames": 0, "tracks": 0, "outputs": 0, "born": 0}

    def tally(nav, out) -> None:
        seen["tracks"] += len(nav.state)
        seen["outputs"] += len(out)

    checked = checked_against_own_updates(update_many, _nav_state, _tracks_bytes, seen, tally)

    monkeypatch.setattr(perception, "rough_update_many", checked)  # (what the batch mode's observe_many calls)
    sc = load_scenario(ROOT / "deploy" / "scenarios" / "sabatini-20-camera-exact.toml").with_overrides(duration_s=600.0)
    res = run_in_process(sc, tmp_path / "run", "eq", record="truth")
    assert res.summary["batch"]["used"] and res.summary["agent_faults"] == {}
    assert seen["frames"] == 60  # every frame of the run (steps 0-59) went through the check
    assert seen["tracks"] > 1000 and seen["outputs"] > 1000 and seen["born"] > 20, seen


def test_update_many_faults_stay_with_their_navigator(monkeypatch) -> None:
    """A raise in the batch's arithmetic (here its first solve) writes nothing: each navigator then
    runs its own update, with its own result. A raise while one navigator's part is written (here its
    next track id) is that navigator's alone: returned in its place, the others' states and outputs
    are their own updates'."""
    camera, shape = Camera(), SpacecraftShape()
    rng = np.random.default_rng(11)
    navs = [RoughNavigator(camera, shape, A_M, N_RADPS) for _ in range(3)]
    real_solve = rough.solve_frames
    for k, (t, u, blobs, acc) in enumerate(_frames(rng, [3, 4, 5], 40, camera, shape)):
        own: list[RoughNavigator | None] = [copy.deepcopy(nav) for nav in navs]
        expect = [nav.update(t, u, b, a) for nav, b, a in zip(own, blobs, acc)]  # type: ignore[union-attr]
        calls: list[int] = []
        if k == 20:  # the batch's solve raises (once): every navigator falls back to its own update
            def once(rhs, *args):
                calls.append(len(rhs))
                if len(calls) == 1:
                    raise FloatingPointError("injected")
                return real_solve(rhs, *args)
            monkeypatch.setattr(rough, "solve_frames", once)
        if k == 30:  # navigator 1's part of the frame cannot be written
            navs[1]._next_id = "not a number"  # type: ignore[assignment]
            own[1] = None
        got = update_many(navs, t, u, blobs, acc)
        monkeypatch.undo()
        if k == 20:
            # the batch's first solve (navigator 0's pairs), then each navigator's own update with pairs
            assert len(calls) == 1 + sum(len(e) > 0 for e in expect) >= 3 and calls[0] == calls[1] > 0
        for r, (nav, mine) in enumerate(zip(navs, own)):
            if mine is None:
                assert isinstance(got[r], TypeError)
                navs[r] = RoughNavigator(camera, shape, A_M, N_RADPS)  # (its state is undefined: the caller resets it)
                continue
            assert _nav_state(nav) == _nav_state(mine), (k, r)
            assert _tracks_bytes(got[r]) == _tracks_bytes(expect[r]), (k, r)
    assert sum(len(nav.state) for nav in navs) >= 8


def test_pair_costs_are_the_matrix_norms() -> None:
    """`pair_costs` over stacked (track, blob) pairs is, pair by pair, the (T, M) matrix of
    np.linalg.norm(pred[:, None] - centroid[None], axis=2) the association's cost had (ties, equal
    points and negative zeros among them)."""
    rng = np.random.default_rng(3)
    for t_, m_ in [(0, 4), (4, 0), (1, 1), (7, 5), (30, 40)]:
        pred = np.round(rng.uniform(-5.0, 1085.0, (t_, 2)), 1)
        cen = np.round(rng.uniform(-5.0, 1085.0, (m_, 2)), 1)
        if t_ and m_:
            cen[0] = pred[0]
            pred[-1] = -0.0
        want = np.linalg.norm(pred[:, None, :] - cen[None, :, :], axis=2)
        ti, bj = np.repeat(np.arange(t_), m_), np.tile(np.arange(m_), t_)
        assert pair_costs(pred, cen, ti, bj).reshape(t_, m_).tobytes() == want.tobytes()
