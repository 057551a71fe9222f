"""Paper 000 on the multi-process stack: deploy/scenarios/capture-10.toml (case i) and capture-20.toml
(case ii), the p000-capture flight software (missions/p000_capture/fsw/) fed by the plant's
p000-landmarks sensor (missions/p000_capture/sense.py), the broadcast link at R_c = 9.5 m (link/node.py).

The fast test flies 30 s of case (i) over Zenoh (one process per agent + plant + link channel) and
in-process, and checks: truth bit for bit between the modes; force and torque limits by norm in the
recorded truth; attitude propagation (unit quaternions, body rates = the recorded torques through
Euler's equation); the channel's counters = the tx messages in the MCAP; agreement with the room's
in-process loop (tests/missions/test_p000_closed_loop.py) on the same initial state.

`python tests/missions/test_p000_stack.py RUN_DIR [RUN_DIR ...]` prints the figures of
docs/paper000.md "On the stack" from run directories.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
for p in (ROOT, ROOT / "tests", ROOT / "tests" / "missions"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

CASE_I = ROOT / "deploy" / "scenarios" / "capture-10.toml"
CASE_II = ROOT / "deploy" / "scenarios" / "capture-20.toml"
DT = 0.05
MASS, F_MAX, TAU_MAX, J = 10.0, 0.1, 0.01, 0.075
STATE_BYTES = 84


def initial_state(n: int, semi_axes: tuple[float, float, float], seed: int = 1):
    """The room loop's initial state (run_capture: positions, then attitudes, from default_rng(seed))."""
    from test_p000_closed_loop import Target, initial_positions

    from swarmhil.missions.p000_capture.fsw import quaternion as quat

    rng = np.random.default_rng(seed)
    r = initial_positions(rng, n, Target(np.array(semi_axes, float)), 1.0)
    q = np.array([quat.normalise(rng.normal(size=4)) for _ in range(n)])
    return r, q


@pytest.mark.parametrize("path,n,axes", [(CASE_I, 10, (2.6, 1.9, 1.4)), (CASE_II, 20, (4.0, 1.3, 1.0))])
def test_scenarios_hold_the_papers_cases_and_the_room_loops_initial_state(path: Path, n: int, axes) -> None:
    from swarmhil.deploy.scenario import load_scenario

    doc = tomllib.loads(path.read_text())
    r, q = initial_state(n, axes)
    assert [s["id"] for s in doc["spacecraft"]] == [f"a{i}" for i in range(n)]
    for i, s in enumerate(doc["spacecraft"]):
        assert np.array_equal(s["position_m"], r[i]) and np.array_equal(s["attitude_q"], q[i])
        assert (s["mass_kg"], s["max_force_n"], s["limit"], s["max_torque_nm"]) == (MASS, F_MAX, "norm", TAU_MAX)
        assert s["inertia_kgm2"] == [J] * 3 and s["velocity_mps"] == [0.0] * 3
    (body,) = doc["body"]
    assert body["shape"] == {"kind": "ellipsoid", "semi_axes_m": list(axes)}
    m = body["motion"]
    assert m["kind"] == "kinematic" and m["position_m"] == [0.0] * 3 and m["velocity_mps"] == [0.01, 0.01, 0.0]
    assert m["spin_axis"] == [0.2, 0.1, 1.0] and m["spin_rate_radps"] == pytest.approx(math.radians(0.72), rel=1e-15)
    assert doc["run"]["step_s"] == DT and doc["run"]["duration_s"] == 550.0 and doc["run"]["seed"] == 1
    assert doc["orbit"]["semi_major_axis_m"] == 6878137.0 and doc["link"]["range_m"] == 9.5
    assert doc["controller"]["decision_period_s"] == DT
    sc = load_scenario(path)
    assert sc.decision_period_steps == 1 and sc.fidelity == "cw"


@pytest.mark.parametrize("path,n,axes", [(CASE_I, 10, (2.6, 1.9, 1.4)), (CASE_II, 20, (4.0, 1.3, 1.0))])
def test_seeded_scenarios_draw_the_room_loops_initial_state(path: Path, n: int, axes, tmp_path: Path) -> None:
    """missions/p000_capture/seeds.py: seed 1 gives the committed file; seed s the room loop's seed-s draw."""
    from swarmhil.missions.p000_capture.seeds import seeded_scenario
    from swarmhil.deploy.scenario import load_scenario

    text = path.read_text()
    assert seeded_scenario(text, 1) == text
    for seed in (2, 3):
        doc = tomllib.loads(seeded_scenario(text, seed))
        r, q = initial_state(n, axes, seed)
        assert doc["run"]["seed"] == seed
        assert [s["position_m"] for s in doc["spacecraft"]] == r.tolist()
        assert [s["attitude_q"] for s in doc["spacecraft"]] == q.tolist()
        out = tmp_path / f"s{seed}.toml"
        p = subprocess.run([sys.executable, "-m", "swarmhil.missions.p000_capture.seeds", str(path), str(seed), str(out)], cwd=ROOT,
                           capture_output=True, text=True, timeout=60)
        assert p.returncode == 0 and tomllib.loads(out.read_text()) == doc, p.stderr
        assert load_scenario(out).seed == seed
    bad = subprocess.run([sys.executable, "-m", "swarmhil.missions.p000_capture.seeds", str(ROOT / "deploy" / "scenarios" / "sabatini-20.toml"),
                          "2", str(tmp_path / "x.toml")], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_capture_params_ignore_the_loaders_max_accel() -> None:
    """deploy/scenario.py passes [actuator].max_accel_mps2 to every controller (the one room edit)."""
    from swarmhil.missions.p000_capture.contract import CaptureParams

    assert CaptureParams.from_dict({"max_accel_mps2": 1e-3}) == CaptureParams()
    with pytest.raises(ValueError, match="unknown"):
        CaptureParams.from_dict({"bogus": 1})


# --- the sensing kind -----------------------------------------------------------------------------
def _ctx(sc, steps: int = 0, torque: np.ndarray | None = None):
    from swarmhil.plant.mission_world import MissionWorld
    from swarmhil.plant.sensing import SensingContext

    w = MissionWorld(sc)
    for _ in range(steps):
        w.step(np.zeros((len(w.ids), 3)), DT, torque)
    pos, vel = w.lvlh()
    return SensingContext(steps, w.t_s, w.u_rad, w.ids, pos, vel, w.alive, w), w


def test_sensing_kind_measures_what_the_room_reads() -> None:
    from swarmhil.bus import swarmhil_pb2 as pb
    from swarmhil.bus.codec import measurements_to_dict
    from swarmhil.deploy.scenario import ScenarioError, load_scenario, plant_config
    from swarmhil.missions.p000_capture.fsw import quaternion as quat
    from swarmhil.missions.p000_capture.fsw.sensing import CaptureSensing
    from swarmhil.missions.p000_capture.contract import Ellipsoid, signed_distance, surface_landmarks
    from swarmhil.plant.sensing import make_sensing
    from swarmhil.missions.p000_capture.contract import dcm
    from swarmhil.missions.p000_capture.sense import inertial_to_cw

    sc = plant_config(load_scenario(CASE_I))
    # 200 steps (10 s) with a torque on every craft: the attitude moves, the CW frame has turned n t
    tau = np.tile([0.002, -0.001, 0.003], (10, 1))
    ctx, w = _ctx(sc, 200, tau)
    kind = make_sensing("p000-landmarks", sc)
    got = [measurements_to_dict(kind.stimulus(ctx, j, pb.Header(step=200))) for j in range(10)]
    again = [measurements_to_dict(make_sensing("p000-landmarks", sc).stimulus(ctx, j, pb.Header(step=200)))
             for j in reversed(range(10))][::-1]
    for a, b in zip(got, again):  # seeded by (seed, step, agent): independent of the order of the calls
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    q_i, w_i = w.attitude_wxyz()
    bt = w.body_truth()[0]
    ell = Ellipsoid(bt.position_m, dcm(bt.attitude_q), np.array([2.6, 1.9, 1.4]))
    lm_body, _ = surface_landmarks(np.array([2.6, 1.9, 1.4]), 400)
    lm_cw = bt.position_m + lm_body @ dcm(bt.attitude_q).T
    seen = 0
    for j, d in enumerate(got):
        s = CaptureSensing.from_dict(d)  # the room's reader accepts every name and shape
        assert np.array_equal(s.position_m, ctx.position_m[j]) and np.array_equal(s.velocity_mps, ctx.velocity_mps[j])
        assert np.array_equal(s.omega_body_radps, w_i[j])
        assert np.allclose(s.omega_body_radps, [0.002 * 10 / J, -0.001 * 10 / J, 0.003 * 10 / J], rtol=1e-12)
        q_cw = inertial_to_cw(q_i[j], w.n_radps, ctx.t_s)
        assert np.array_equal(s.q_body_to_lvlh, q_cw)
        # the CW frame turns at +n about z: a frame vector's CW coordinates are R_z(-n t) times inertial ones
        c, sn = math.cos(w.n_radps * ctx.t_s), math.sin(w.n_radps * ctx.t_s)
        rz = np.array([[c, sn, 0], [-sn, c, 0], [0, 0, 1]])
        assert np.allclose(quat.to_dcm(q_cw), rz @ dcm(q_i[j]), atol=1e-14)
        # returns: true landmarks through the own attitude, within noise; cone, range; outliers flagged
        pts = s.position_m + s.landmarks_body_m @ quat.to_dcm(q_cw).T
        good = s.landmark_ids >= 0
        assert np.all(np.abs(pts[good] - lm_cw[s.landmark_ids[good]]) < 0.02 * 6)
        rel = pts - s.position_m
        bore = quat.to_dcm(q_cw)[:, 0]
        assert np.all(rel[good] @ bore >= math.cos(math.radians(37.5)) * np.linalg.norm(rel[good], axis=1) - 0.2)
        assert np.all(np.linalg.norm(rel, axis=1) <= 8.5 + 0.15)
        seen += good.sum()
        sd = signed_distance(ell, s.position_m)
        assert (s.surface_rel_m is not None) == (sd <= 5.5)
        if s.surface_rel_m is not None:
            assert abs(np.linalg.norm(s.surface_rel_m) - sd) < 1e-9
    assert seen > 0
    ids = ctx.ids
    nb = kind.stimulus(ctx, 0, pb.Header(step=200)).neighbours
    d = np.linalg.norm(ctx.position_m - ctx.position_m[0], axis=1)
    assert sorted(n.id for n in nb) == sorted(ids[k] for k in range(1, 10) if d[k] <= 5.5)
    with pytest.raises(ScenarioError, match="sensing.params"):
        load_scenario(CASE_I, sets=["sensing.params.bogus=1"])
    with pytest.raises(ValueError, match="target_id"):
        make_sensing("p000-landmarks", plant_config(load_scenario(CASE_I, sets=['sensing.params.target_id="nope"'])))


# --- reading a run back ---------------------------------------------------------------------------
def load_run(run_dir: Path) -> dict:
    """Truth, telemetry modes and isl/tx packets of a run directory (run.mcap + summary.json)."""
    from conftest import read_mcap

    run_dir = Path(run_dir)
    summary = json.loads((run_dir / "summary.json").read_text())
    truths, modes, tx, est = {}, {}, [], {}
    for topic, _lt, _pt, msg in read_mcap(run_dir / "run.mcap"):
        if topic == "truth":
            truths[int(msg.header.step)] = msg
        elif topic.startswith("sc/") and topic.endswith("/tm"):
            modes.setdefault(msg.header.source, {})[int(msg.header.step)] = msg.mode
            if len(msg.items):  # the controller's estimates (Telemetry.items), as plain lists
                est.setdefault(msg.header.source, {})[int(msg.header.step)] = {
                    it.name: list(it.values) for it in msg.items}
        elif topic.startswith("isl/tx/"):
            tx.append((msg.src, msg.type, len(msg.payload), int(msg.header.step)))
    steps = sorted(truths)
    assert steps == list(range(len(steps))), "truth has gaps"
    tr = [truths[k] for k in steps]
    ids = [b.id for b in tr[0].bodies if b.kind == "spacecraft"]

    def rows(field: str, kind: str = "spacecraft", quat: bool = False) -> np.ndarray:
        if quat:
            return np.array([[[getattr(b, field).w, getattr(b, field).x, getattr(b, field).y, getattr(b, field).z]
                              for b in m.bodies if b.kind == kind] for m in tr])
        return np.array([[[getattr(b, field).x, getattr(b, field).y, getattr(b, field).z]
                          for b in m.bodies if b.kind == kind] for m in tr])

    return {
        "summary": summary, "ids": ids, "t": np.array([m.header.t for m in tr]),
        "pos": rows("position_m"), "vel": rows("velocity_mps"), "accel": rows("accel_cmd_mps2"),
        "q": rows("attitude", quat=True), "w": rows("angular_velocity_radps"), "tau": rows("torque_cmd_nm"),
        "target_pos": rows("position_m", "target")[:, 0], "target_q": rows("attitude", "target", quat=True)[:, 0],
        "modes": modes, "tx": tx, "est": est,
    }


def metrics(run: dict) -> dict:
    """The figures of docs/paper000.md "On the stack" from the recorded truth, telemetry and link
    (the shared computations are the report section's, missions/p000_capture/report/__init__.py)."""
    from swarmhil.missions.p000_capture.report import chase_entry, link_by_type, pair_distance, surface_distance, target_axes

    s = run["summary"]
    axes = target_axes(s["config"])
    pos, t = run["pos"], run["t"]
    pair = pair_distance(pos)
    surf = surface_distance(pos, run["target_pos"], run["target_q"], axes, np.arange(0, len(t), 10))
    entry, chase_steps = chase_entry(run["modes"], DT)
    by_type = {typ: [sum(c["tx_messages"] for c in rows.values()), sum(c["tx_payload_bytes"] for c in rows.values())]
               for typ, rows in link_by_type(s["channel"]["links"], s["channel"].get("link_columns")).items()}
    state_msgs, state_bytes = by_type.get("p000-state", [0, 0])
    hz1 = chase_steps * DT  # one state packet per chase/dock agent-second
    return {
        "in_chase": sum(1 for sid in run["ids"] if run["modes"][sid][max(run["modes"][sid])] != "search"),
        "entry_s": entry, "min_pair_m": float(pair.min()), "min_surface_m": float(surf.min()),
        "final_surface_m": [round(float(x), 2) for x in surf[-1]],
        "state_msgs": state_msgs, "state_bytes": state_bytes, "by_type": by_type,
        "chase_agent_steps": chase_steps, "every_step_ratio": state_msgs / max(chase_steps, 1),
        "hz1_ratio": state_msgs / max(hz1, 1e-9), "hz1_bytes": hz1 * STATE_BYTES,
        "totals": s["channel"]["totals"], "wall_s": s["wall_s"],
    }


def swarmhil_run(scenario: Path, out: Path, *extra: str) -> dict:
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(scenario), "--out", str(out), "--no-progress", *extra]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=3600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return load_run(out)


def assert_stack_run(mp: dict, ip: dict, steps: int) -> dict:
    s = mp["summary"]
    assert s["process_mode"] == "multi-process" and ip["summary"]["process_mode"] == "in-process"
    assert s["steps"] == steps and not s["dead_agents"] and not s["agent_faults"] and s["rejected_packets"] == 0
    # no agent lost and rejoined on the way (a dropped session coasts the spacecraft for a step or
    # two: found under load when agents ran their step on Zenoh's network thread, deploy/proc.py)
    assert not s.get("rejoins"), s.get("rejoins")
    assert set(s["exit_codes"].values()) == {0}
    # 1. the same truth bit for bit on Zenoh and on the in-memory bus, and the same link traffic
    for k in ("t", "pos", "vel", "accel", "q", "w", "tau", "target_pos", "target_q"):
        assert np.array_equal(mp[k], ip[k]), k
    assert mp["modes"] == ip["modes"] and sorted(mp["tx"]) == sorted(ip["tx"])
    assert s["channel"]["links"] == ip["summary"]["channel"]["links"]
    # 2. limits by norm in the recorded truth (force = m a; the torque applied over each step)
    assert np.linalg.norm(mp["accel"], axis=2).max() * MASS <= F_MAX * (1 + 1e-12)
    assert np.linalg.norm(mp["tau"], axis=2).max() <= TAU_MAX * (1 + 1e-12)
    # 3. attitude: unit quaternions; J dω = τ dt exactly (J = 0.075 I: ω × Jω = 0); the quaternion
    #    turns by the mean rate over the step (to the commutator term ~ dt³ |ω × ω̇| / 12: measured
    #    4e-7 against a turn of up to ~5e-3 per step)
    from swarmhil.missions.p000_capture.fsw import quaternion as quat

    assert np.abs(np.linalg.norm(mp["q"], axis=2) - 1).max() < 1e-12
    dw = np.diff(mp["w"], axis=0)
    np.testing.assert_allclose(dw, mp["tau"][1:] * DT / J, rtol=0, atol=1e-14)
    w_mean = 0.5 * (mp["w"][1:] + mp["w"][:-1])
    worst = 0.0
    for k in range(0, steps, 7):
        for i in range(len(mp["ids"])):
            pred = quat.propagate(mp["q"][k, i], w_mean[k, i], DT)
            worst = max(worst, min(np.abs(pred - mp["q"][k + 1, i]).max(), np.abs(pred + mp["q"][k + 1, i]).max()))
    assert worst < 2e-6
    # 4. link: the channel counted exactly the packets the agents sent (the MCAP's isl/tx messages)
    tot = s["channel"]["totals"]
    assert tot["tx_messages"] == len(mp["tx"]) and tot["tx_payload_bytes"] == sum(x[2] for x in mp["tx"])
    m = metrics(mp)
    for typ, (msgs, pay) in m["by_type"].items():
        assert msgs == sum(1 for x in mp["tx"] if x[1] == typ)
        assert pay == sum(x[2] for x in mp["tx"] if x[1] == typ)
    assert m["state_bytes"] == STATE_BYTES * m["state_msgs"]
    assert tot["dropped_lost"] == tot["dropped_queue"] == tot["dropped_occulted"] == 0
    assert s["channel"]["forced_windows"] == 0 and s["channel"]["late_packets"] == 0
    # 5. no collision, nobody inside the target
    assert m["min_pair_m"] > 0.5 and m["min_surface_m"] > 0.0
    return m


SHORT_S = 30.0


def room_loop(duration_s: float):
    """The room's in-process loop (test_p000_closed_loop.run_capture, case i, seed 1, dt 0.05) with
    the positions it integrates recorded (its rk4_cw wrapped)."""
    import test_p000_closed_loop as cl

    rows: list[np.ndarray] = []
    orig = cl.rk4_cw

    def rec(r, v, a, dt):
        rows.append(r.copy())
        return orig(r, v, a, dt)

    cl.rk4_cw = rec
    try:
        res = cl.run_capture(duration_s=duration_s, dt_s=DT, seed=1)
    finally:
        cl.rk4_cw = orig
    return res, np.array(rows)


def test_capture10_flies_multi_process_over_zenoh(tmp_path: Path) -> None:
    """30 s of case (i): multi-process over Zenoh and in-process, compared with each other and with
    the room's loop. Measured (docs/paper000.md): 3 agents in chase by 22 s."""
    steps = int(round(SHORT_S / DT))
    mp = swarmhil_run(CASE_I, tmp_path / "mp", "--duration", str(SHORT_S))
    ip = swarmhil_run(CASE_I, tmp_path / "ip", "--duration", str(SHORT_S), "--in-process")
    m = assert_stack_run(mp, ip, steps)
    print({k: v for k, v in m.items() if k != "final_surface_m"}, "wall mp", mp["summary"]["wall_s"],
          "ip", ip["summary"]["wall_s"])
    # the room's loop on the same initial state: the same physics to 1e-12 m until the first mode
    # change in either loop (19.25 s in the room's); then they part: the landmark noise draws differ
    # and the plant flies attitude in inertial axes, reported in the CW frame that has turned n t
    # (1.1 deg at 18 s) where the room's loop takes the CW frame as inertial, so the cone's edges
    # differ; the first fits from a small patch are fragile (stack: a2 detects at 17.7 s, fits at
    # 21.7 s). Measured: room a2, a1, a8 at 19.25-19.3 s; stack the same three at 21.70-21.75 s, or
    # 22.70-22.75 s with other floating-point kernels (below).
    res, room_pos = room_loop(SHORT_S)
    room_entry = {f"a{i}": round(x, 2) for i, x in enumerate(res.chase_entry_s) if x is not None}
    k0 = int(round(min(min(m["entry_s"].values()), min(room_entry.values())) / DT))
    assert k0 > 300 and np.abs(mp["pos"][:k0] - room_pos[:k0]).max() < 1e-9
    assert len(m["entry_s"]) >= 3 and m["entry_s"].keys() <= room_entry.keys()
    # the same three agents enter chase first in both loops, the stack later: its first fits come
    # from a small patch and a last-bit difference moves a fit to the next attempt. Measured gap
    # (issue 24, docs/determinism.md): 2.45 s on AVX-512 and on AVX2 with the Sandybridge BLAS
    # kernels, 3.45 s on AVX2 with its own; one more such step of margin
    assert set(sorted(m["entry_s"], key=m["entry_s"].get)[:3]) == set(sorted(room_entry, key=room_entry.get)[:3])
    assert 2.0 < min(m["entry_s"].values()) - min(room_entry.values()) < 4.5
    assert m["state_msgs"] > 0 and m["by_type"]["p000-landmarks"][0] > 0


def test_capture20_first_seconds_in_process(tmp_path: Path) -> None:
    """Case (ii), 5 s in-process (~20 s wall): as in the room's loop, one agent fits at t = 0 and
    Event 2 spreads through R_c: all 20 in chase by 0.2 s (NOTES-000 trap 9)."""
    run = swarmhil_run(CASE_II, tmp_path / "ip", "--duration", "5", "--in-process")
    m = metrics(run)
    assert m["in_chase"] == 20 and max(m["entry_s"].values()) <= 0.2
    assert run["summary"]["channel"]["totals"]["tx_messages"] == len(run["tx"])
    assert np.linalg.norm(run["accel"], axis=2).max() * MASS <= F_MAX * (1 + 1e-12)
    assert np.linalg.norm(run["tau"], axis=2).max() <= TAU_MAX * (1 + 1e-12)


@pytest.mark.system
@pytest.mark.study  # ~30 min: too long for CI's hour; CI runs the room's 550 s case (i) loop instead
@pytest.mark.timeout(5400)  # three 550 s runs: ~500 + ~700 + ~630 s wall at load ~15, + reading 3 x 250 MB MCAPs
def test_system_capture10_full_length_on_the_stack(tmp_path: Path) -> None:
    """Case (i), 550 s at 0.05 s over Zenoh (event trigger), and the 1 Hz periodic policy in-process:
    the paper's outcomes from the recorded truth and the channel's counters (docs/paper000.md)."""
    steps = int(round(550.0 / DT))
    mp = swarmhil_run(CASE_I, tmp_path / "mp")
    ip = swarmhil_run(CASE_I, tmp_path / "ip", "--in-process")
    m = assert_stack_run(mp, ip, steps)
    per = metrics(swarmhil_run(CASE_I, tmp_path / "per", "--in-process",
                               "--set", 'controller.params.broadcast="periodic"'))
    print(m, per, sep="\n")
    assert m["in_chase"] == 10 and max(m["entry_s"].values()) < 325.6       # Fig. 3: all enclose
    assert m["min_pair_m"] > 3.0 and m["min_surface_m"] > 0.0               # no collisions, outside the target
    assert m["state_msgs"] < 0.05 * m["chase_agent_steps"]                  # << every step
    assert m["state_bytes"] < 0.7 * per["state_bytes"]                      # fewer bytes than 1 Hz (link-counted)


def final_estimates(run: dict) -> tuple[float, int]:
    """(worst relative error of the agents' last sorted semi-axes estimates in telemetry against the
    sorted truth, number of agents with an estimate)."""
    true_axes = np.sort(np.asarray(run["summary"]["config"]["body"][0]["shape"]["semi_axes_m"], dtype=float))
    errs = [float(np.max(np.abs(np.array(by_step[max(by_step)]["p000_axes_est_m"]) - true_axes) / true_axes))
            for by_step in run["est"].values()]
    return max(errs, default=float("inf")), len(errs)


@pytest.mark.system
@pytest.mark.study  # one 550 s case (ii) run over Zenoh + one in-process: ~25-40 min wall on the shared box
@pytest.mark.timeout(5400)
def test_study_capture20_full_length_on_the_stack(tmp_path: Path) -> None:
    """Case (ii), 20 agents, 550 s at 0.05 s over Zenoh (21 processes + link channel) and in-process:
    bit for bit the same truth and link rows; the issue's done-when outcomes on the governed law:
    nobody inside the true target, every agent's sorted semi-axes estimate within 2 % at the end."""
    steps = int(round(550.0 / DT))
    mp = swarmhil_run(CASE_II, tmp_path / "mp")
    ip = swarmhil_run(CASE_II, tmp_path / "ip", "--in-process")
    m = assert_stack_run(mp, ip, steps)
    assert mp["est"] == ip["est"]
    worst, n_est = final_estimates(mp)
    print(m, worst, n_est, sep="\n")
    assert m["in_chase"] == 20 and n_est == 20
    assert m["min_surface_m"] > 0.0 and worst <= 0.02
    assert m["state_msgs"] < 0.05 * m["chase_agent_steps"]


def report(run_dir: Path) -> None:
    m = metrics(load_run(run_dir))
    print(run_dir, {k: (round(v, 4) if isinstance(v, float) else v) for k, v in m.items()})


if __name__ == "__main__":
    for d in sys.argv[1:]:
        report(Path(d))
