"""Splits of the swarm and each navigation layer against truth per step (issue 36,
dashboards/navreport/diagnosis.py), on a real run with an injected split.

The run: the shipped rendered-camera + EKF scenario with 4 spacecraft for 600 s, in-process with
every packet recorded, and sc04 (the one ahead, seen by the three others) pushed cross-track by a
thruster stuck on at 2 mm/s^2 from 60 s (docs/faults.md), twice what the controller can command:
it leaves the field of view and the range of the others and the swarm splits (measured: at step 48,
sc02 -> sc04 and sc01 -> sc04 lost at the split, sc03 -> sc04 five steps before). The references
are computed here from the messages decoded with the standard MCAP readers: visibility by the
plant's rule per truth message, components by the tests' own union-find, track matching by a plain
nearest-neighbour loop over the telemetry.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SCENARIOS, components_by_hand, read_mcap
from swarmhil.dashboards.navreport.analysis import analyse_run
from swarmhil.dashboards.navreport.diagnosis import false_rows, split_rows, splits, step_series
from swarmhil.dashboards.navreport.read import DecisionRows, TrackRows
from swarmhil.deploy.cli import main
from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

FAULT = """
[[fault]]
name = "push-sc04"
kind = "thruster_stuck_on"
targets = ["sc04"]
accel_mps2 = [0.0, 0.0, 2e-3]
start_s = 60.0
"""
CAM = CameraGeometry(500.0, 1080, 1000.0)  # the scenario's [camera]


@pytest.fixture(scope="module")
def split_run(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("navsplit")
    scenario = d / "push.toml"
    scenario.write_text((SCENARIOS / "sabatini-20-camera-filter.toml").read_text() + FAULT)
    res = CliRunner().invoke(main, ["run", str(scenario), "--in-process", "--duration", "600", "--set", "dispersion.count=4",
                                    "--out", str(d / "run"), "--no-progress"])
    assert res.exit_code == 0, res.output
    return d / "run"


def _by_hand(run_dir: Path):
    truth, tms = {}, {}
    for topic, _l, _p, m in read_mcap(run_dir / "run.mcap"):
        if topic == "truth":
            truth[int(m.header.step)] = m
        elif topic.startswith("sc/") and topic.endswith("/tm"):
            tms[(topic.split("/")[1], int(m.header.step))] = m
    ids = [b.id for b in next(iter(truth.values())).bodies]
    steps = sorted(truth)
    pos = {s: np.array([[b.position_m.x, b.position_m.y, b.position_m.z] for b in truth[s].bodies]) for s in steps}
    roe = {s: np.array([list(b.roe_m) for b in truth[s].bodies]) for s in steps}
    vis = {s: visibility_matrix(pos[s], CAM, np.array([b.alive for b in truth[s].bodies])) for s in steps}
    return ids, steps, truth, tms, pos, roe, vis


def test_report_nav_names_the_lost_edges_of_the_injected_split_and_what_navigation_believed(split_run, tmp_path):
    ids, steps, _truth, tms, pos, roe, vis = _by_hand(split_run)
    n = len(ids)
    comps = {s: components_by_hand(n, zip(*np.nonzero(vis[s]))) for s in steps}
    ncomp = {s: len(set(c)) for s, c in comps.items()}
    hand_splits = [s for a, s in zip(steps, steps[1:]) if ncomp[a] == 1 and ncomp[s] > 1]
    assert hand_splits, "the injected fault did not split the swarm"
    first = hand_splits[0]
    assert first * 10.0 > 60.0  # after the thruster stuck on
    lab = comps[first]
    hand_edges = {(ids[j], ids[k]) for j, k in zip(*np.nonzero(vis[first - 1])) if lab[j] != lab[k]}
    assert hand_edges and all(k == "sc04" for _j, k in hand_edges), hand_edges  # the pushed one is cut off

    res = CliRunner().invoke(main, ["report-nav", str(split_run), "--out", str(tmp_path / "cmp")])
    assert res.exit_code == 0, res.output
    assert f"split(s) of the visibility graph at steps {first}" in res.output
    for j, k in hand_edges:
        assert f"{j} -> {k}: last seen step {first - 1}," in res.output
    out = split_run / "navreport"
    doc = json.loads((out / "nav_splits.json").read_text())
    assert [s["step"] for s in doc["splits"]] == hand_splits
    sp = doc["splits"][0]
    assert sorted(map(sorted, sp["components"])) == sorted(
        sorted(ids[i] for i in range(n) if lab[i] == c) for c in set(lab))
    at_split = {(e["observer"], e["neighbour"]) for e in sp["lost_edges"] if e["lost_at_split"]}
    assert at_split == hand_edges
    # the edges lost earlier in the window: crossing the new partition, present some step before and gone at first - 1
    w0 = sp["window_start_step"]
    assert w0 == max(steps[0], first - 10)
    earlier = {(ids[j], ids[k]) for s in range(w0, first - 1) for j, k in zip(*np.nonzero(vis[s]))
               if lab[j] != lab[k]} - hand_edges
    assert {(e["observer"], e["neighbour"]) for e in sp["lost_edges"] if not e["lost_at_split"]} == earlier
    summary = json.loads((out / "nav_summary.json").read_text())
    assert summary["splits"]["splits"] == len(hand_splits)
    assert set(summary["splits"]["lost_edges_at_first_split"]) == {f"{j}->{k}" for j, k in hand_edges}

    col = {sid: i for i, sid in enumerate(ids)}
    n_tracked = 0
    for e in sp["lost_edges"]:
        j, k = col[e["observer"]], col[e["neighbour"]]
        last = e["last_seen_step"]
        assert vis[last][j, k] and not vis[last + 1][j, k]
        # why it went, clause by clause of the plant's rule, at the first step without it
        rel = pos[last + 1][k] - pos[last + 1][j]
        cause = set(e["cause"])
        assert ("range" in cause) == (np.linalg.norm(rel) > 500.0)
        assert ("fov" in cause) == (rel[1] > 0 and max(abs(rel[0]), abs(rel[2])) > 0.54 * rel[1])
        for side, (a, b) in (("belief_observer", (j, k)), ("belief_neighbour", (k, j))):
            entries = e[side]
            assert [x["step"] for x in entries] == list(range(w0, first + 1))
            for x in entries:
                s = x["step"]
                true_rel = pos[s][b] - pos[s][a]
                assert x["truly_visible"] == bool(vis[s][a, b])
                assert x["truth"]["range_m"] == pytest.approx(np.linalg.norm(true_rel), abs=1e-9)
                margin = 1000.0 * (0.54 - max(abs(true_rel[0]), abs(true_rel[2])) / true_rel[1]) if true_rel[1] > 0 else None
                assert x["truth"]["fov_margin_px"] == (None if margin is None else pytest.approx(margin, abs=1e-6))
                # the observer's tracks at that step, each matched to its nearest true neighbour by a plain loop
                tm = tms[(ids[a], s)]
                mine = []
                for tr in tm.tracks:
                    est = np.array([tr.position_m.x, tr.position_m.y, tr.position_m.z])
                    d = {c: np.linalg.norm(est - (pos[s][c] - pos[s][a])) for c in range(n) if c != a}
                    if min(d, key=d.get) == b:
                        mine.append((d[b], tr, est))
                if not mine:
                    assert x["track"] is None and x["tracks_on_neighbour"] == 0
                    continue
                _d, tr, est = min(mine, key=lambda t: t[0])
                got = x["track"]
                assert got["id"] == tr.track and x["tracks_on_neighbour"] == len(mine)
                assert got["used_by_controller"] == any(dd.neighbour == tr.track for dd in tm.decisions)
                dd = [d for d in tm.decisions if d.neighbour == tr.track]
                if dd:  # the controller's decision on it: behaviour and acceleration, along the true line of sight
                    acc = np.array([dd[0].accel_mps2.x, dd[0].accel_mps2.y, dd[0].accel_mps2.z])
                    assert x["decision"]["behaviour"] == dd[0].behaviour
                    assert x["decision"]["accel_towards_neighbour_mps2"] == pytest.approx(
                        acc @ true_rel / np.linalg.norm(true_rel), abs=1e-15)
                else:
                    assert x["decision"] is None
                assert got["range_err_m"] == pytest.approx(np.linalg.norm(est) - np.linalg.norm(true_rel), abs=1e-9)
                e_roe = np.array(tr.roe_m) - (roe[s][b] - roe[s][a])
                assert got["da_err_m"] == pytest.approx(e_roe[0], abs=1e-9)
                assert got["de_err_m"] == pytest.approx(np.hypot(e_roe[2], e_roe[3]), abs=1e-9)
                assert got["di_err_m"] == pytest.approx(np.hypot(e_roe[4], e_roe[5]), abs=1e-9)
                assert np.allclose(got["sigma_roe_m"], np.sqrt(np.diag(np.reshape(tr.covariance_m2, (6, 6)))))
                if a == j and s <= last:
                    n_tracked += 1
        v = e["observer_view"]
        assert v["step"] == last and v["steps_in_window"] == last - w0 + 1
    # the observers did track the neighbour that went away (EKF tracks through the push), and the page says so
    assert n_tracked > 0
    page = (out / "index.html").read_text()
    assert "Splits of the swarm" in page and all(f"{j} -&gt; {k}" in page for j, k in hand_edges)
    assert (out / "steps.png").is_file() and "## Split at step" in (out / "nav_splits.md").read_text()


def test_per_step_comparison_against_truth_of_the_split_run(split_run):
    """Components, visible pairs, and the visible pairs without a matched track per step, counted here
    from the messages (tracks matched by a plain loop, false by the same gate)."""
    ids, steps, _truth, tms, pos, _roe, vis = _by_hand(split_run)
    n = len(ids)
    doc = json.loads((split_run / "navreport" / "nav_steps.json").read_text()) if (
        split_run / "navreport" / "nav_steps.json").is_file() else None
    nav = analyse_run(split_run)
    ser = step_series(nav)
    assert ser.step.tolist() == steps
    assert ser.components.tolist() == [len(set(components_by_hand(n, zip(*np.nonzero(vis[s]))))) for s in steps]
    assert ser.visible_pairs.tolist() == [int(vis[s].sum()) for s in steps]
    tracked, reported = {}, {}
    false = 0
    for s in steps:
        t = np.zeros((n, n), bool)
        reported[s] = np.array([(ids[j], s) in tms for j in range(n)])[:, None]
        for j in range(n):
            tm = tms.get((ids[j], s))
            for tr in (tm.tracks if tm is not None else []):
                est = np.array([tr.position_m.x, tr.position_m.y, tr.position_m.z])
                d = {c: np.linalg.norm(est - (pos[s][c] - pos[s][j])) for c in range(n) if c != j}
                k = min(d, key=d.get)
                if d[k] <= max(20.0, 0.1 * np.linalg.norm(est)):
                    t[j, k] = True
                else:
                    false += 1
        tracked[s] = t
    # the agents' last telemetry is of the step before the run's last truth: its visible pairs are not counted
    assert ser.no_telemetry.tolist() == [int((vis[s] & ~reported[s]).sum()) for s in steps]
    assert ser.no_telemetry[-1] == ser.visible_pairs[-1] > 0 and ser.no_telemetry[:-1].sum() == 0
    untracked = [int((vis[s] & ~tracked[s] & reported[s]).sum()) for s in steps]
    assert (ser.missed + ser.lost).tolist() == untracked
    lost = [0] + [int((vis[s] & ~tracked[s] & reported[s] & tracked[p]).sum()) for p, s in zip(steps, steps[1:])]
    assert ser.lost.tolist() == lost
    assert int(ser.false_tracks.sum()) == false == int(false_rows(nav).sum())
    assert ser.swaps.sum() == 0  # the EKF associates on the likelihood: no track jumps to another spacecraft here
    # the layers: the used tracks are a subset of the matched ones, and the decisions are one per used track
    for q in ("range_m", "velocity_mps", "da_m"):
        assert np.all(ser.layers["used"][q]["count"] <= ser.layers["tracks"][q]["count"])
    assert ser.layers["decisions"]["da_m"]["count"].sum() == ser.layers["used"]["da_m"]["count"].sum() + int(
        (nav.rows.used & false_rows(nav)).sum())
    if doc is not None:
        assert doc["missed"] == ser.missed.tolist() and doc["components"] == ser.components.tolist()


def _nav(vis: np.ndarray, pos: np.ndarray, rows: TrackRows, dec: DecisionRows):
    """A RunNav of hand-made arrays (no recording)."""
    from types import SimpleNamespace

    from swarmhil.dashboards.navreport.analysis import RunNav, associate

    T, N, _ = pos.shape
    truth = SimpleNamespace(step=np.arange(T), t_s=10.0 * np.arange(T), ids=[f"s{i}" for i in range(N)], n_bodies=N,
                            n_steps=T, position_m=pos, velocity_mps=np.zeros_like(pos), roe_m=np.zeros((T, N, 6)),
                            alive=np.ones((T, N), bool), run="hand")
    return RunNav(truth, rows, associate(rows, truth), dec, np.zeros((dec.step.size, 6)), {}, vis, CAM)


def test_splits_swaps_and_breaks_on_hand_made_arrays():
    """Three spacecraft: 1 sees 2 throughout; 0 sees 1 until step 3 and 2 until step 1: the split is
    at step 4 ({0} | {1, 2}), 0 -> 1 lost at it and 0 -> 2 two steps before. One track of 0 follows 1,
    then jumps to 2 (a swap); at step 2 another track id has 1 (a break); at step 3 two tracks have 1
    (a duplicate, the nearer is the belief); at step 4 a track has nobody near (false)."""
    T = 6
    pos = np.zeros((T, 3, 3))
    pos[:, 1] = (0.0, 100.0, 0.0)
    pos[:, 2] = (0.0, 200.0, 0.0)
    vis = np.zeros((T, 3, 3), bool)
    vis[:4, 0, 1] = True
    vis[:2, 0, 2] = True
    vis[:, 1, 2] = True
    rows_t, n, _lab = split_rows(vis)
    assert rows_t.tolist() == [4] and n.tolist() == [1, 1, 1, 1, 2, 2]
    est = [(0, 0, (0, 100, 0)), (1, 0, (0, 101, 0)), (2, 0, (0, 199, 0)),  # track 0: s1, s1, then s2 (swap)
           (2, 1, (0, 100, 0)), (3, 1, (0, 100, 0)), (3, 2, (0, 99, 0)),  # track 1 on s1 at 2, 3; track 2 on s1 at 3
           (4, 3, (0, 400, 0))]  # track 3: nothing within the gate (false)
    R = len(est)
    rows = TrackRows(step=np.array([e[0] for e in est]), observer=np.zeros(R, int), track=np.array([e[1] for e in est]),
                     track_names=["s0/a", "s0/b", "s0/c", "s0/d"], position_m=np.array([e[2] for e in est], float),
                     velocity_mps=np.zeros((R, 3)), roe_m=np.zeros((R, 6)), covariance_m2=np.full((R, 6, 6), np.nan),
                     age_steps=np.zeros(R, int), used=np.array([e[:2] == (2, 1) for e in est]))
    # the controller acted on track b at step 2: attraction, 0.1 mm/s^2 along +y, i.e. towards s1
    dec = DecisionRows(np.array([2]), np.array([0]), ["b"], np.zeros((1, 6)), ["attraction"], np.array([[0.0, 1e-4, 0.0]]))
    nav = _nav(vis, pos, rows, dec)
    sp = splits(nav, before_steps=3)
    assert len(sp) == 1 and sp[0]["step"] == 4
    edges = {(e["observer"], e["neighbour"]): e for e in sp[0]["lost_edges"]}
    assert set(edges) == {("s0", "s1"), ("s0", "s2")}
    assert edges[("s0", "s1")]["lost_at_split"] and edges[("s0", "s1")]["last_seen_step"] == 3
    assert not edges[("s0", "s2")]["lost_at_split"] and edges[("s0", "s2")]["last_seen_step"] == 1
    b = {x["step"]: x for x in edges[("s0", "s1")]["belief_observer"]}
    assert [b[s]["track"]["id"] if b[s]["track"] else None for s in range(1, 5)] == ["a", "b", "b", None]
    assert b[3]["tracks_on_neighbour"] == 2  # b and c: the nearer, b, is the belief
    assert b[2]["track"]["used_by_controller"] and not b[3]["track"]["used_by_controller"]
    assert b[2]["decision"]["behaviour"] == "attraction" and b[3]["decision"] is None
    assert b[2]["decision"]["accel_towards_neighbour_mps2"] == pytest.approx(1e-4)
    v = edges[("s0", "s1")]["observer_view"]
    assert (v["step"], v["had_track"], v["id"], v["controller_acting"]) == (3, True, "b", False)
    assert (v["steps_in_window"], v["steps_tracked"], v["steps_acted_on"]) == (3, 3, 1)
    ser = step_series(nav)
    assert ser.swaps.tolist() == [0, 0, 1, 0, 0, 0]
    assert ser.breaks.tolist() == [0, 0, 1, 0, 0, 0]  # s1: track a at step 1, b at step 2
    assert ser.duplicate_tracks.tolist() == [0, 0, 0, 1, 0, 0]
    assert ser.false_tracks.tolist() == [0, 0, 0, 0, 1, 0]
    # 1 -> 2 never tracked (1 has no tracks); 0 -> 2 not tracked at steps 0, 1
    assert ser.lost.tolist() == [0, 0, 0, 0, 0, 0] and ser.missed.tolist() == [2, 2, 1, 1, 1, 1]
