"""Issue 29: the batch mode of papers 001, 003 and 004 (the mission worlds: cw and inertial plants,
sensing kinds that send `Measurements`, packets over the link) gives the truth of the per-agent
in-process run, bit for bit: every truth message (positions, velocities, the commands in force,
dV) equal, with equal log times, and the link carried the same packets (deploy/batch.py
`BatchLink` against the channel companion, link/node.py)."""
from __future__ import annotations

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
# paper 001 (far layer), and 100 steps of it in the shaping and near layers (LatticeController.step_batch)
CASES = [("servicing-6", "servicing-6", 60.0, []), ("surround-6", "surround-6", 60.0, []),
         ("tersoff-6", "tersoff-6", 1000.0, []), ("tersoff-6-cluster", "tersoff-6", 500.0, CLUSTER)]


@pytest.mark.parametrize("case,name,duration,sets", CASES, ids=[c[0] for c in CASES])
def test_mission_batch_truth_equals_the_per_agent_run(tmp_path: Path, case: str, name: str, duration: float,
                                                      sets: list[str]) -> None:
    sc = load_scenario(SCENARIOS / f"{name}.toml", sets).with_overrides(duration_s=duration)
    full = run_in_process(sc, tmp_path / "all", "same")
    batch = run_in_process(sc, tmp_path / "truth", "same", record="truth")
    assert full.summary.get("batch") is None and batch.summary["batch"] == {"used": True, "why_not": None}
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
    pairs = 0
    for r, j in enumerate(rows.tolist()):
        o = observation_from_rel(kind.stimulus(ctx, j, header("run", "plant", 3, 15.0, 0)))
        a, b = rel.offsets[r], rel.offsets[r + 1]
        assert [sc.ids[k] for k in rel.neighbour[a:b]] == o.neighbour_ids
        assert np.array_equal(rel.rel_position_m[a:b], o.rel_position_m.reshape(-1, 3))
        assert np.array_equal(rel.rel_velocity_mps[a:b], o.rel_velocity_mps.reshape(-1, 3))
        assert rel.extra is not None and rel.extra[r].keys() == o.extra.keys()
        for key, value in o.extra.items():
            assert rel.extra[r][key].tobytes() == value.tobytes(), key
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
