"""Two-satellite validation cases of paper 002 (Fig. 5 collision avoidance, Fig. 6 alignment).

Each test reads its scenario file (deploy/scenarios/sabatini-2-*.toml), runs both spacecraft's
controllers every 10 s step on what their cameras see (range <= 500 m and the square field of view
along +y, plant/sensors.py), and propagates the truth with the plant's exact ZOH linear ROE model
(plant/dynamics/roe_linear.py). Checks are on the truth, in metres.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmhil.missions.p002_sabatini.fsw.sabatini import parallelism
from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.plant.dynamics import roe_linear as truth
from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

SCENARIOS = Path(__file__).resolve().parents[1] / "deploy" / "scenarios"


@dataclass
class Run:
    roe_m: np.ndarray  # (steps + 1, N, 6) truth ROE
    pos_m: np.ndarray  # (steps + 1, N, 3) truth LVLH positions
    accel_mps2: np.ndarray  # (steps, N, 3)
    visible: np.ndarray  # (steps, N, N)
    modes: list[list[str]]
    delta_v_mps: np.ndarray  # (N,)


def simulate(scenario: dict, params_override: dict | None = None) -> Run:
    a_m = scenario["orbit"]["semi_major_axis_m"]
    n = truth.mean_motion(a_m)
    u0 = np.radians(scenario["orbit"]["u0_deg"])
    dt = scenario["run"]["step_s"]
    steps = int(round(scenario["run"]["duration_s"] / dt))
    cam = CameraGeometry(**scenario["camera"])
    params = dict(scenario["controller"]["params"], **(params_override or {}))
    ids = [sc["id"] for sc in scenario["spacecraft"]]
    ctrls = [make_controller(scenario["controller"]["name"], sid, OrbitInfo(a_m, n), params) for sid in ids]
    max_accel = scenario["actuator"]["max_accel_mps2"]
    roe = np.array([sc["roe_m"] for sc in scenario["spacecraft"]], dtype=float)
    roes, poss, accs, viss, modes = [roe], [], [], [], []
    for k in range(steps):
        u = u0 + n * k * dt
        pos, vel = truth.roe_to_lvlh(roe, u, n)
        vis = visibility_matrix(pos, cam)
        acc = np.zeros((len(ids), 3))
        step_modes = []
        for j, ctrl in enumerate(ctrls):
            nb = np.flatnonzero(vis[j])
            cmd = ctrl.step(Observation(k, k * dt, u, [ids[i] for i in nb], pos[nb] - pos[j], vel[nb] - vel[j]))
            acc[j] = np.clip(cmd.accel_mps2, -max_accel, max_accel)
            step_modes.append(cmd.mode)
        roe = truth.propagate_roe(roe, acc, u, n, dt)
        roes.append(roe)
        poss.append(pos)
        accs.append(acc)
        viss.append(vis)
        modes.append(step_modes)
    poss.append(truth.roe_to_lvlh(roe, u0 + n * steps * dt, n)[0])
    accs = np.array(accs)
    return Run(np.array(roes), np.array(poss), accs, np.array(viss), modes,
               np.linalg.norm(accs, axis=2).sum(axis=0) * dt)


def load(name: str) -> dict:
    with open(SCENARIOS / name, "rb") as f:
        return tomllib.load(f)


def d_min_m(rel_roe_m: np.ndarray) -> np.ndarray:
    return np.abs(rel_roe_m[..., 1]) - 2.0 * np.linalg.norm(rel_roe_m[..., 2:4], axis=-1)


def test_collision_avoidance_fig5():
    """The follower sees the leader inside d_min, runs CA only, and ends beyond d_min without collision."""
    sc = load("sabatini-2-collision.toml")
    d_min, d_min_trans = sc["controller"]["params"]["d_min_m"], sc["controller"]["params"]["d_min_trans_m"]
    run = simulate(sc)
    rel = run.roe_m[:, 1] - run.roe_m[:, 0]  # follower relative to leader
    assert d_min_m(rel[0]) < d_min and run.visible[0, 1, 0] and run.modes[0][1] == "collision_avoidance"
    assert not run.visible[:, 0, 1].any()  # the leader never sees the follower: only j acts
    assert np.all(run.delta_v_mps[0] == 0.0) and run.delta_v_mps[1] > 0.0
    # the follower raised its orbit and drifts back: along-track separation grows beyond d_min
    assert rel[-1, 0] > 0.0
    assert d_min_m(rel[-1]) > d_min
    along_track_m = run.pos_m[:, 0, 1] - run.pos_m[:, 1, 1]
    assert along_track_m[-1] > d_min and abs(rel[-1, 1]) > d_min
    # no collision along the way: the range never falls below the transverse safety distance
    assert np.min(np.linalg.norm(run.pos_m[:, 0] - run.pos_m[:, 1], axis=1)) > d_min_trans
    # de and di were driven parallel (section 3.5)
    assert parallelism(rel[-1]) > 0.95


def test_collision_case_with_all_behaviours_settles_drift_free():
    """Same start with alignment and attraction enabled: the pair ends separated and drift-free."""
    sc = load("sabatini-2-collision.toml")
    sc["run"]["duration_s"] = 6 * 3600.0
    run = simulate(sc, {"enable_alignment": True, "enable_attraction": True})
    rel = run.roe_m[:, 1] - run.roe_m[:, 0]
    assert d_min_m(rel[-1]) > sc["controller"]["params"]["d_min_m"]
    assert abs(rel[-1, 0]) < 0.1  # a da: drift below 1.5 n * 0.1 m = 0.6 m per hour
    assert {"collision_avoidance", "alignment", "attraction"} <= {m[1] for m in run.modes}


def test_alignment_fig6():
    """Drift, too small di and orthogonal de/di -> drift-free, parallel, transverse size in bounds."""
    sc = load("sabatini-2-alignment.toml")
    p = sc["controller"]["params"]
    run = simulate(sc)
    rel = run.roe_m[:, 1] - run.roe_m[:, 0]
    assert p["d_min_m"] < d_min_m(rel[0]) < p["attraction_fraction"] * p["d_max_m"]
    assert parallelism(rel[0]) < p["parallel_min"] and np.linalg.norm(rel[0, 4:6]) < p["d_min_trans_m"]
    assert run.visible[:, 1, 0].all()  # the follower keeps the leader in view throughout
    final = rel[-1]
    assert abs(final[0]) < 0.05  # a da [m]: drift-free
    last_hour = rel[-361:]  # no along-track drift over the last hour
    assert np.ptp(last_hour[:, 1]) < 1.0
    assert parallelism(final) > 0.99
    de_m, di_m = np.linalg.norm(final[2:4]), np.linalg.norm(final[4:6])
    pos = run.pos_m[-1]
    d_max_trans = p["fov_margin"] * np.linalg.norm(pos[0] - pos[1]) * np.tan(np.radians(p["fov_half_angle_deg"]))
    for size in (de_m, di_m):
        assert p["d_min_trans_m"] <= size <= d_max_trans
    assert p["d_min_m"] < d_min_m(final) < p["attraction_fraction"] * p["d_max_m"]
