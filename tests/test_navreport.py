"""Navigation error from a recording (dashboards/navreport.py): association with truth, errors, NEES.

A short real in-process run of the filter scenario (6 spacecraft, 300 s) and of the ideal-sensing
scenario; the references are computed here independently, from the messages decoded with the
standard MCAP readers (conftest.read_mcap) and from the scene stimuli the agents received.
"""
from __future__ import annotations

import json
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import chi2

from conftest import SCENARIOS, read_mcap
from dashboards.navreport import (
    TrackRows, associate, nees_of, read_tracks, write_comparison, write_nav_report, analyse_run,
)
from deploy.launcher import run_in_process
from deploy.scenario import parse_scenario


def _small(name: str, count: int, duration_s: float) -> dict:
    doc = tomllib.loads((SCENARIOS / name).read_text())
    doc["dispersion"]["count"] = count
    doc["run"]["duration_s"] = duration_s
    return doc


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("navrep")
    out = {}
    for label, name, dur in (("filter", "sabatini-20-camera-filter.toml", 300.0), ("ideal", "sabatini-20.toml", 100.0)):
        sc = parse_scenario(_small(name, 6, dur), name)
        run_in_process(sc, base / label, f"nr-{label}")
        out[label] = base / label
    return out


def _messages(run_dir: Path, run: str):
    truth, tms, scenes = {}, [], {}
    for topic, _lt, _pt, m in read_mcap(run_dir / "run.mcap"):
        if topic == "truth":
            truth[int(m.header.step)] = m
        elif topic.endswith("/tm") and topic.startswith("sc/"):
            tms.append((topic.split("/")[1], m))
        elif topic.startswith("sc/") and topic.endswith("/sense/scene"):
            scenes[(topic.split("/")[1], int(m.header.step))] = {b.id for b in m.bodies}
    return truth, tms, scenes


def test_tracks_associate_with_the_spacecraft_in_view_and_errors_match_an_independent_computation(runs):
    run_dir = runs["filter"]
    nav = analyse_run(run_dir)
    rows, err, truth = nav.rows, nav.err, nav.truth
    truth_msgs, tms, scenes = _messages(run_dir, "nr-filter")
    assert rows.n == sum(len(m.tracks) for _sid, m in tms) > 50
    assert np.all(err.neighbour >= 0) and np.all(err.neighbour != rows.observer)
    # every associated spacecraft was in the observer's scene stimulus of that step, or of one of the
    # previous five steps (a confirmed track coasts up to EkfConfig.max_misses = 5 frames)
    in_view = [any(truth.ids[k] in scenes.get((truth.ids[j], int(s) - d), ()) for d in range(6))
               for j, k, s in zip(rows.observer, err.neighbour, rows.step)]
    assert np.mean(in_view) == 1.0
    # independent errors for every row, straight from the decoded messages
    by_key = {}
    for sid, m in tms:
        for tr in m.tracks:
            by_key[(sid, int(m.header.step), tr.track)] = tr
    for r in range(rows.n):
        j, k, s = truth.ids[rows.observer[r]], truth.ids[err.neighbour[r]], int(rows.step[r])
        tr = by_key[(j, s, rows.track_names[rows.track[r]].split("/", 1)[1])]
        bodies = {b.id: b for b in truth_msgs[s].bodies}
        bj, bk = bodies[j], bodies[k]
        true_rel = np.array([bk.position_m.x - bj.position_m.x, bk.position_m.y - bj.position_m.y,
                             bk.position_m.z - bj.position_m.z])
        est = np.array([tr.position_m.x, tr.position_m.y, tr.position_m.z])
        np.testing.assert_allclose(err.position_err_m[r], est - true_rel, atol=1e-9)
        np.testing.assert_allclose(err.roe_err_m[r], np.array(tr.roe_m) - (np.array(bk.roe_m) - np.array(bj.roe_m)), atol=1e-9)
        # nearest among the others, by a plain loop
        d = {b.id: np.linalg.norm(est - (np.array([b.position_m.x, b.position_m.y, b.position_m.z])
                                        - np.array([bj.position_m.x, bj.position_m.y, bj.position_m.z])))
             for b in truth_msgs[s].bodies if b.id != j}
        assert min(d, key=d.get) == k
    # a filter on 1080 px images: converged tracks are good to metres, much less than the spacing
    assert np.median(np.linalg.norm(err.position_err_m, axis=1)) < 5.0
    assert np.all(err.second_m > err.assoc_m)
    assert nav.summary["identity_switches"] == 0
    nees = err.nees[np.isfinite(err.nees)]
    assert nees.size == rows.n  # the EKF reports a covariance on every track


def test_decisions_of_ideal_sensing_have_zero_roe_error(runs):
    """With the plant's exact `rel` stimulus the controller's dalpha_jk must equal roe_j - roe_k of
    the truth: checks the sign convention of the decision error (NOTES-002)."""
    nav = analyse_run(runs["ideal"])
    assert nav.rows.n == 0
    assert nav.decision_err.shape[0] > 10
    assert np.nanmax(np.abs(nav.decision_err)) < 1e-6


def _truth(pos: np.ndarray, roe: np.ndarray) -> SimpleNamespace:
    T, N, _ = pos.shape
    return SimpleNamespace(step=np.arange(T), t_s=10.0 * np.arange(T), ids=[f"s{i}" for i in range(N)], n_bodies=N,
                           position_m=pos, velocity_mps=np.zeros_like(pos), roe_m=roe)


def test_association_picks_the_nearest_and_counts_identity_switches():
    """Observer 0 at the origin; spacecraft 1 and 2 cross each other along y. One track follows
    the estimate (0, 100 + 2 k, 0): it is nearest to 1 first, then to 2 (one identity switch)."""
    T = 5
    pos = np.zeros((T, 3, 3))
    pos[:, 1, 1] = 100.0 + 10.0 * np.arange(T)  # 100 .. 140
    pos[:, 2, 1] = 150.0 - 10.0 * np.arange(T)  # 150 .. 110
    roe = np.zeros((T, 3, 6))
    roe[:, :, 1] = pos[:, :, 1]
    est = np.column_stack([np.zeros(T), 100.0 + 2.0 * np.arange(T), np.zeros(T)])
    rows = TrackRows(step=np.arange(T), observer=np.zeros(T, int), track=np.zeros(T, int), track_names=["s0/e0"],
                     position_m=est, velocity_mps=np.zeros((T, 3)), roe_m=np.column_stack([np.zeros(T), est[:, 1], np.zeros((T, 4))]),
                     covariance_m2=np.full((T, 6, 6), np.nan), age_steps=np.arange(T), used=np.ones(T, bool))
    err = associate(rows, _truth(pos, roe))
    truth_near = [1 if abs(est[t, 1] - pos[t, 1, 1]) < abs(est[t, 1] - pos[t, 2, 1]) else 2 for t in range(T)]
    assert err.neighbour.tolist() == truth_near == [1, 1, 1, 2, 2]
    assert err.switches.tolist() == [False, False, False, True, False]
    np.testing.assert_allclose(err.position_err_m[:, 1], est[:, 1] - pos[np.arange(T), err.neighbour, 1])
    np.testing.assert_allclose(err.roe_err_m[:, 1], err.position_err_m[:, 1])
    assert np.all(np.isnan(err.nees))


def test_nees_of_gaussian_errors_follows_chi_square_6():
    rng = np.random.default_rng(3)
    n = 4000
    a = rng.normal(size=(n, 6, 6))
    cov = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(6)
    e = np.einsum("rij,rj->ri", np.linalg.cholesky(cov), rng.normal(size=(n, 6)))
    nees = nees_of(e, cov)
    lo, hi = chi2.ppf([0.001, 0.999], 6 * n) / n
    assert lo < nees.mean() < hi
    assert abs(np.mean(nees <= chi2.ppf(0.95, 6)) - 0.95) < 0.015
    cov[0] = np.nan
    assert np.isnan(nees_of(e[:2], cov[:2])[0]) and np.isfinite(nees_of(e[:2], cov[:2])[1])


def test_reports_and_comparison_are_written(runs, tmp_path):
    page = write_nav_report(runs["filter"])
    out = page.parent
    s = json.loads((out / "nav_summary.json").read_text())
    assert s["track_rows"] > 0 and s["all_tracks"]["position_m"]["count"] == s["track_rows"]
    assert 0.0 < s["coverage_of_visible_pairs"] <= 1.0
    assert {"pairs.png", "error_time.png", "nees_time.png"} <= {p.name for p in out.glob("*.png")}
    md = write_comparison([runs["ideal"], runs["filter"]], tmp_path / "cmp", labels=["ideal", "filter"])
    lines = md.read_text().splitlines()
    assert len(lines) == 4 and lines[2].startswith("| ideal |") and lines[3].startswith("| filter |")
    rows = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    assert rows[0]["dv_ratio"] == 1.0 and rows[1]["delta_v_total_mps"] >= 0.0


def test_read_tracks_of_a_run_without_telemetry_tracks(runs):
    nav = analyse_run(runs["ideal"])
    rows, _dec = read_tracks(runs["ideal"] / "run.mcap", nav.truth.run, nav.truth.ids)
    assert rows.n == 0 and rows.position_m.shape == (0, 3)
