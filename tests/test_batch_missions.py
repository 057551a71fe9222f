"""Issue 29: the batch mode of papers 000, 001, 003 and 004 (the mission worlds: cw and inertial plants,
sensing kinds that send `Measurements`, packets over the link) gives the truth of the per-agent
in-process run, bit for bit: every truth message (positions, velocities, the commands in force,
dV) equal, with equal log times, and the link carried the same packets (deploy/batch.py
`BatchLink` against the channel companion, link/node.py)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from swarmhil.bus import swarmhil_pb2 as pb
from conftest import SCENARIOS
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario


def _truths(path: Path) -> list[tuple[int, bytes]]:
    with open(path, "rb") as f:
        return [(m.log_time, m.data) for _s, ch, m in make_reader(f).iter_messages(log_time_order=False)
                if ch.topic == "truth"]


# paper 001 inside the sensing ball: five in the shaping ball (Tersoff-Brenner forces), one in the near layer
CLUSTER = [f"spacecraft.{i}.position_m={p}" for i, p in enumerate(
    ["[3.0,9.0,1.0]", "[-2.0,-8.0,4.0]", "[1.0,4.0,-9.0]", "[0.5,-5.0,-7.0]", "[60.0,10.0,5.0]", "[-2.0,7.0,8.5]"])]
# (id, scenario, simulated seconds, --set): 60 s of 0.1 s steps for papers 004 and 003, 200 steps of
# paper 001 (far layer), 100 steps of it in the shaping and near layers (LatticeController.step_batch),
# and 600 steps of paper 000's case (i) (attitude flown: torques; landmark fits and packets from ~15 s)
CASES = [("servicing-6", "servicing-6", 60.0, []), ("surround-6", "surround-6", 60.0, []),
         ("tersoff-6", "tersoff-6", 1000.0, []), ("tersoff-6-cluster", "tersoff-6", 500.0, CLUSTER),
         ("capture-10", "capture-10", 30.0, [])]


@pytest.mark.parametrize("case,name,duration,sets", CASES, ids=[c[0] for c in CASES])
def test_mission_batch_truth_equals_the_per_agent_run(tmp_path: Path, case: str, name: str, duration: float,
                                                      sets: list[str]) -> None:
    sc = load_scenario(SCENARIOS / f"{name}.toml", sets).with_overrides(duration_s=duration)
    full = run_in_process(sc, tmp_path / "all", "same", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "truth", "same", record="truth")
    assert not full.summary["batch"]["used"] and batch.summary["batch"] == {"used": True, "why_not": None}
    a, b = _truths(tmp_path / "all" / "run.mcap"), _truths(tmp_path / "truth" / "run.mcap")
    assert len(a) == sc.steps + 1 and a == b
    last = pb.Truth.FromString(b[-1][1])
    acc = np.array([[x.accel_cmd_mps2.x, x.accel_cmd_mps2.y, x.accel_cmd_mps2.z] for x in last.bodies
                    if x.kind == "spacecraft"])
    assert np.abs(acc).max() > 0  # the flight software commanded something
    assert batch.summary["delta_v_total_mps"] == full.summary["delta_v_total_mps"] > 0
    assert batch.summary["agent_faults"] == full.summary["agent_faults"] == {}
    if "channel" in full.summary:  # the same packets sent and delivered
        assert batch.summary["channel"]["totals"] == full.summary["channel"]["totals"]
        assert batch.summary["channel"]["totals"]["rx_messages"] > 0


@pytest.mark.parametrize("dead", [(), (2,)], ids=["all-alive", "one-dead"])
def test_relative_kind_batch_equals_its_messages(dead: tuple[int, ...]) -> None:
    """Paper 001's sensing kind (`relative`, own state) as arrays: for spacecraft a few metres apart
    (neighbours in and out of the 21 m ball, a dead one), every observer's neighbours, relative
    states and own state equal what the agent reads from its message (agent/node.py)."""
    from swarmhil.agent.node import observation_from_rel
    from swarmhil.bus.codec import header
    from swarmhil.deploy.scenario import plant_config
    from swarmhil.plant.sensing import SensingContext, make_sensing

    sc = load_scenario(SCENARIOS / "tersoff-6.toml")
    kind = make_sensing("relative", plant_config(sc))
    rng = np.random.default_rng(7)
    pos, vel = rng.uniform(-20.0, 20.0, (6, 3)), rng.normal(0.0, 0.1, (6, 3))
    pos[4] = -0.0  # a zero component: the message path's +0.0
    alive = np.ones(6, dtype=bool)
    alive[list(dead)] = False
    ctx = SensingContext(step=3, t_s=15.0, u_rad=0.1, ids=list(sc.ids), position_m=pos, velocity_mps=vel,
                         alive=alive, world=None)
    rows = np.flatnonzero(alive)
    rel = kind.batch(ctx, rows)
    if not dead:  # the plant's word that all are alive: the same arrays without the mask
        told = kind.batch(dataclasses.replace(ctx, all_alive=True), rows)
        for a, b in ((told.offsets, rel.offsets), (told.neighbour, rel.neighbour), (told.rel_position_m, rel.rel_position_m)):
            assert a.tobytes() == b.tobytes()
    pairs = 0
    for r, j in enumerate(rows.tolist()):
        o = observation_from_rel(kind.stimulus(ctx, j, header("run", "plant", 3, 15.0, 0)))
        a, b = rel.offsets[r], rel.offsets[r + 1]
        assert [sc.ids[k] for k in rel.neighbour[a:b]] == o.neighbour_ids
        assert np.array_equal(rel.rel_position_m[a:b], o.rel_position_m.reshape(-1, 3))
        assert np.array_equal(rel.rel_velocity_mps[a:b], o.rel_velocity_mps.reshape(-1, 3))
        assert rel.extra is not None and rel.extra[r].keys() == o.extra.keys()
        for key, value in o.extra.items():
            assert rel.extra[r][key].tobytes() == value.tobytes() and rel.extra[r][key].shape == value.shape, key
        pairs += b - a
    assert 0 < pairs < len(rows) * (len(rows) - 1)  # some neighbours in range, some out


@pytest.mark.parametrize("dead", [(), (2,)], ids=["all-alive", "one-dead"])
def test_p004_partial_batch_equals_its_messages(dead: tuple[int, ...]) -> None:
    """Paper 004's sensing kind (`p004-partial`) as arrays (issue 29): every observer's named arrays
    (d_ij to its live graph neighbours, y_i) equal, byte for byte and key for key, what the agent reads
    from its message (agent/node.py), noise included; no neighbour rows."""
    from swarmhil.agent.node import observation_from_rel
    from swarmhil.bus.codec import header
    from swarmhil.deploy.scenario import plant_config
    from swarmhil.plant.mission_world import MissionWorld
    from swarmhil.plant.sensing import SensingContext, make_sensing

    sc = load_scenario(SCENARIOS / "servicing-6.toml")
    cfg = plant_config(sc)
    kind, world = make_sensing("p004-partial", cfg), MissionWorld(cfg)
    world.step(np.random.default_rng(4).normal(0, 1, (6, 3)), 0.1)
    world.alive[list(dead)] = False
    pos, vel = world.lvlh()
    rows = np.flatnonzero(world.alive)
    for step in (1, 7):
        def ctx() -> SensingContext:
            return SensingContext(step=step, t_s=0.1, u_rad=world.u_rad, ids=list(sc.ids), position_m=pos,
                                  velocity_mps=vel, alive=world.alive, world=world)
        rel = kind.batch(ctx(), rows)
        assert rel.offsets.tolist() == [0] * (len(rows) + 1) and rel.rel_position_m.shape == (0, 3)
        for r, j in enumerate(rows.tolist()):
            o = observation_from_rel(kind.stimulus(ctx(), j, header("run", "plant", step, 0.1, 0)))
            assert o.neighbour_ids == [] and list(rel.extra[r]) == list(o.extra)
            for key, value in o.extra.items():
                assert rel.extra[r][key].tobytes() == value.tobytes() and rel.extra[r][key].shape == value.shape, key
            assert any(k.startswith("p004.y_m/") for k in o.extra)
        measured_s3 = any("p004.d_m/s3" in e for e in rel.extra)  # a dead neighbour is not measured
        assert measured_s3 is (2 not in dead)


def test_p003_relative_batch_equals_its_messages() -> None:
    """Paper 003's sensing kind (`p003-relative`) as arrays (issue 29), noise-free: the leader's target
    measurement and each servicer's leader-relative state equal, byte for byte and key for key, what
    the agent reads from its message; a target beyond the range is not measured; with noise the kind
    has no batch form (its draws stay in the messages' order)."""
    from swarmhil.agent.node import observation_from_rel
    from swarmhil.bus.codec import header
    from swarmhil.deploy.scenario import plant_config
    from swarmhil.plant.mission_world import MissionWorld
    from swarmhil.plant.sensing import SensingContext, make_sensing

    sc = load_scenario(SCENARIOS / "surround-6.toml")
    cfg = plant_config(sc)
    world = MissionWorld(cfg)
    world.step(np.random.default_rng(3).normal(0, 0.1, (7, 3)), 0.1)
    pos, vel = world.lvlh()
    rows = np.arange(7)
    for range_m in (5000.0, 10.0):
        kind = make_sensing("p003-relative", plant_config(load_scenario(
            SCENARIOS / "surround-6.toml", [f"sensing.params.range_m={range_m}"])))

        def ctx() -> SensingContext:
            return SensingContext(step=1, t_s=0.1, u_rad=world.u_rad, ids=list(sc.ids), position_m=pos,
                                  velocity_mps=vel, alive=world.alive, world=world)
        rel = kind.batch(ctx(), rows)
        assert rel.offsets.tolist() == [0] * 8 and rel.rel_position_m.shape == (0, 3)
        for r in rows.tolist():
            o = observation_from_rel(kind.stimulus(ctx(), r, header("run", "plant", 1, 0.1, 0)))
            assert list(rel.extra[r]) == list(o.extra) and (len(o.extra) == 2 or (r == 0 and range_m == 10.0))
            for key, value in o.extra.items():
                assert rel.extra[r][key].tobytes() == value.tobytes() and rel.extra[r][key].shape == value.shape, key
    noisy = make_sensing("p003-relative", plant_config(load_scenario(
        SCENARIOS / "surround-6.toml", ["sensing.params.position_noise_m=0.1"])))
    assert not hasattr(noisy, "batch")


@pytest.mark.parametrize("dead", [(), (3,)], ids=["all-alive", "one-dead"])
def test_p000_kind_batch_equals_its_messages(dead: tuple[int, ...]) -> None:
    """Paper 000's sensing kind (`p000-landmarks`) as arrays: on capture-20's first truth, every
    observer's neighbours and relative states, and every named measurement (attitude, rate, own
    state, landmark returns and ids, the surface within R_h), equal what the agent reads from its
    message (agent/node.py), shapes and bits."""
    from swarmhil.agent.node import observation_from_rel
    from swarmhil.bus.codec import header
    from swarmhil.deploy.scenario import plant_config
    from swarmhil.plant.mission_world import MissionWorld
    from swarmhil.plant.sensing import SensingContext, make_sensing

    cfg = plant_config(load_scenario(SCENARIOS / "capture-20.toml"))
    world = MissionWorld(cfg)
    alive = np.ones(len(cfg.ids), dtype=bool)
    alive[list(dead)] = False
    pos, vel = world.lvlh()
    ctx = SensingContext(step=7, t_s=0.35, u_rad=0.1, ids=list(cfg.ids), position_m=pos, velocity_mps=vel,
                         alive=alive, world=world)
    rows = np.flatnonzero(alive)
    rel = make_sensing("p000-landmarks", cfg).batch(ctx, rows)
    kind = make_sensing("p000-landmarks", cfg)  # (a fresh kind: nothing cached from the batch)
    pairs = returns = surfaces = 0
    for r, j in enumerate(rows.tolist()):
        o = observation_from_rel(kind.stimulus(ctx, j, header("run", "plant", 7, 0.35, 0)))
        a, b = rel.offsets[r], rel.offsets[r + 1]
        assert [cfg.ids[k] for k in rel.neighbour[a:b]] == o.neighbour_ids
        assert rel.rel_position_m[a:b].tobytes() == o.rel_position_m.reshape(-1, 3).tobytes()
        assert rel.rel_velocity_mps[a:b].tobytes() == o.rel_velocity_mps.reshape(-1, 3).tobytes()
        assert rel.owner is not None and (rel.owner[a:b] == r).all()
        assert rel.extra is not None and list(rel.extra[r]) == list(o.extra)
        for key, value in o.extra.items():
            got = rel.extra[r][key]
            assert got.dtype == value.dtype and got.shape == value.shape and got.tobytes() == value.tobytes(), key
        pairs += b - a
        returns += len(o.extra["p000_landmarks_body_m"])
        surfaces += "p000_surface_rel_m" in o.extra
    assert pairs > 0 and returns > 0 and surfaces > 0  # neighbours, landmark returns, surface proximity seen


def test_p000_visibility_of_many_sensors_equals_each_ones() -> None:
    """`visible_landmarks` over N sensors at once, row j, equals sensor j's alone, and so do the
    distances, facing and cone products it compares (the norm, einsum and matmul of a stack against
    each sensor's own: the same bits), for random target poses and sensors whose boresights are
    columns of their attitude matrices (strided, as the kind passes them)."""
    from scipy.spatial.transform import Rotation

    from swarmhil.missions.p000_capture.contract import dcm, surface_landmarks
    from swarmhil.missions.p000_capture.sense import P000Params, visible_landmarks

    p = P000Params()
    rng = np.random.default_rng(3)
    lm0, nrm0 = surface_landmarks(np.array([4.0, 1.3, 1.0]), 400)
    seen = 0
    for trial in range(40):
        rot = Rotation.random(random_state=trial).as_matrix()
        lm, nrm = rng.normal(size=3) + lm0 @ rot.T, nrm0 @ rot.T
        q = rng.normal(size=(20, 4))
        att = dcm(q / np.linalg.norm(q, axis=1, keepdims=True))
        pos = rng.uniform(-10.0, 10.0, (20, 3))
        pos[:5] = lm[rng.integers(0, 400, 5)] * 1.8  # some right in front of the surface
        rel = lm[None, :, :] - pos[:, None, :]
        vis = visible_landmarks(rel, nrm, att[:, :, 0], p)
        for j in range(20):
            alone = visible_landmarks(lm - pos[j], nrm, att[j][:, 0], p)
            assert np.array_equal(vis[j], alone), (trial, j)
            assert np.einsum("ij,nij->ni", nrm, -rel)[j].tobytes() == np.einsum("ij,ij->i", nrm, -(lm - pos[j])).tobytes()
            assert np.matmul(rel, att[:, :, 0][:, :, None])[j, :, 0].tobytes() == ((lm - pos[j]) @ att[j][:, 0]).tobytes()
            seen += int(alone.sum())
    assert seen > 0


def test_p000_batch_path_handles_a_raising_spacecraft_as_the_agent_node(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Paper 000's step_batch: a spacecraft whose flight software raises (here a3 at steps 40-42,
    after perception and its state's updates, where `step` raises too) commands zero and is counted
    as a controller fault, as the agent node counts it; the others fly on: the same truth, faults
    and dV as the per-agent run."""
    from swarmhil.missions.p000_capture.fsw import controller as cc

    act = cc.CaptureController._act

    def raising(self: cc.CaptureController, obs, *args, **kw):  # type: ignore[no-untyped-def]
        plan = act(self, obs, *args, **kw)
        if self.sc_id == "a3" and 40 <= obs.step <= 42:
            raise RuntimeError("injected")
        return plan

    monkeypatch.setattr(cc.CaptureController, "_act", raising)
    sc = load_scenario(SCENARIOS / "capture-10.toml").with_overrides(duration_s=3.0)
    full = run_in_process(sc, tmp_path / "all", "same")
    batch = run_in_process(sc, tmp_path / "truth", "same", record="truth")
    assert batch.summary["batch"]["used"]
    assert _truths(tmp_path / "all" / "run.mcap") == _truths(tmp_path / "truth" / "run.mcap")
    assert batch.summary["agent_faults"] == full.summary["agent_faults"] == {"a3": {"controller": 3}}
    assert batch.summary["delta_v_total_mps"] == full.summary["delta_v_total_mps"] > 0


def test_a_batchs_subset_is_the_batch_of_its_observations() -> None:
    """agent/controller.py `ObservationBatch.subset` (a class's rows of a mixed batch, issue 29: paper
    003's servicers beside the leader) equals `ObservationBatch.of` of those observers' observations."""
    from swarmhil.agent.controller import Observation, ObservationBatch

    rng = np.random.default_rng(34)
    for _ in range(200):
        n = int(rng.integers(1, 8))
        obs = [Observation(step=3, t_s=0.3, u_rad=0.1, neighbour_ids=[f"n{k}" for k in range(c)],
                           rel_position_m=rng.normal(size=(c, 3)), rel_velocity_mps=rng.normal(size=(c, 3)),
                           extra={"k": k}, isl_rx=[k]) for k, c in enumerate(rng.integers(0, 4, n).tolist())]
        batch = ObservationBatch.of([f"o{k}" for k in range(n)], obs)
        rows = sorted(rng.choice(n, int(rng.integers(1, n + 1)), replace=False).tolist())
        got = batch.subset(rows)
        want = ObservationBatch.of([batch.observers[i] for i in rows], [batch.observation(i) for i in rows])
        assert (got.observers, got.neighbour_ids, got.extra, got.isl_rx) == (want.observers, want.neighbour_ids,
                                                                              want.extra, want.isl_rx)
        for name in ("offsets", "rel_position_m", "rel_velocity_mps"):
            a, b = getattr(got, name), getattr(want, name)
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_named_rows_are_the_list_of_dicts_they_stand_for() -> None:
    """bus/codec.py NamedRows (the `relative` kind's own states as arrays, issue 29) reads as the
    list of per-observer dicts: length, indexing (negative too), slices, iteration and key order."""
    from swarmhil.bus.codec import NamedRows

    a, b = np.arange(12.0).reshape(4, 3), -np.arange(12.0).reshape(4, 3)
    rows = NamedRows({"p": a, "v": b}, 4)
    want = [{"p": a[r], "v": b[r]} for r in range(4)]
    assert len(rows) == 4 and rows.rows == {"p": a, "v": b}
    for got, w in zip(list(rows), want, strict=True):
        assert list(got) == ["p", "v"] and all(got[k].tobytes() == w[k].tobytes() for k in w)
    assert rows[-1]["v"].tobytes() == b[3].tobytes() and [d["p"][0] for d in rows[1:3]] == [3.0, 6.0]
    assert any("v" in d for d in rows) and not any("x" in d for d in rows)
    with pytest.raises(IndexError):
        rows[4]
