"""Paper 003 on the multi-process stack: deploy/scenarios/surround-6.toml flown by `swarmhil run`
(plant, recorder, link channel and one agent process per spacecraft over Zenoh on loopback), read
back from the MCAP with the standard reader (tests/conftest.py read_mcap).

Checked from the recorded truth: the leader's TT error inside the funnel, the servicers' CT errors
as the in-process loop of test_p003_closed_loop.py predicts, no sphere intrusion, thrust limits
(truth accel_cmd_mps2), and the link packets the channel counted (summary.json). The in-process
stack (`--in-process`) must give the same truth bit for bit.

`python tests/missions/test_p003_stack.py RUN_DIR` prints the figures of docs/paper003.md from a
run directory.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[2]
for p in (ROOT, ROOT / "tests"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

SCENARIO = ROOT / "deploy" / "scenarios" / "surround-6.toml"
ESCAPE_N = 3.0               # per axis (docs/paper003.md, choice: Fig. 5 is missing)
TARGET_MASS_KG = 300.0
ESCAPE_DIRECTIONS = ((1.0, 1.0, 1.0), (1.0, -1.0, 0.0), (0.0, 1.0, -1.0))
PIECE_S, FILTERED_S, SEGMENT_S = 0.5, 15.0, 100.0


def escape_manoeuvres(escape_n: float = ESCAPE_N) -> list[dict]:
    """The escape manoeuvre of the closed-loop test as [[body]] manoeuvres (constant accelerations):
    u_Ts = F x direction on [0,100), [100,200), [200,300) s, filtered by u_T'' + 1.8 u_T' + u_T = u_Ts
    (§5). Each piece holds the filter output's exact mean over it (same impulse): 0.5 s pieces over the
    first 15 s after each switch (the filter settles as e^{-0.9 t}: 1.4e-6 left at 15 s), then one piece
    to the next switch."""
    edges = []
    for s in range(3):
        t0 = s * SEGMENT_S
        edges += [t0 + PIECE_S * i for i in range(int(FILTERED_S / PIECE_S))]
    edges.append(3 * SEGMENT_S)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:  # per axis: u, u', ∫u
        seg = min(int(t // SEGMENT_S), 2)
        u_s = escape_n * np.asarray(ESCAPE_DIRECTIONS[seg])
        u, ud = y[0:3], y[3:6]
        return np.concatenate([ud, u_s - 1.8 * ud - u, u])

    y = np.zeros(9)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        sol = solve_ivp(rhs, (a, b), y, method="DOP853", rtol=1e-12, atol=1e-14)
        y_new = sol.y[:, -1]
        mean_n = (y_new[6:9] - y[6:9]) / (b - a)
        out.append({"t_start_s": a, "t_end_s": b,
                    "accel_mps2": [float(round(v / TARGET_MASS_KG, 15)) + 0.0 for v in mean_n]})
        y = y_new
    return out


def test_scenario_holds_the_generated_escape_and_structure() -> None:
    from swarmhil.missions.p003_surround.contract import sphere_arrays

    doc = tomllib.loads(SCENARIO.read_text())
    body = doc["body"][0]
    got = body["motion"]["manoeuvres"]
    want = escape_manoeuvres()
    assert len(got) == len(want)
    for g, w in zip(got, want):
        assert (g["t_start_s"], g["t_end_s"]) == (w["t_start_s"], w["t_end_s"])
        # the file was written from solve_ivp at rtol 1e-12, rounded to 15 decimals: the solver's own
        # error (~1e-14 m/s^2 on ~6e-3) and the kernels' last bits (another CPU: 1e-15 after the
        # rounding, issue 24) are far inside rtol 1e-9; a wrong direction, force or filter is not
        np.testing.assert_allclose(g["accel_mps2"], w["accel_mps2"], rtol=1e-9, atol=1e-15)
    c, r = sphere_arrays()
    assert np.array_equal(np.asarray(body["shape"]["centers_m"]), c)
    assert np.array_equal(np.asarray(body["shape"]["radii_m"]), r)


# --- reading a run back ---------------------------------------------------------------------------
def load_run(run_dir: Path) -> dict:
    """Truth and commands of a run directory, from run.mcap (standard reader) and summary.json.

    truth: t (K,), ids, pos/vel (K, N, 3) spacecraft in the scenario frame (the leader's LVLH),
    accel (K, N, 3) applied over the step that ended at t, target pos/vel (K, 3);
    cmd: {id: (K-1, 3)} the agents' commanded accelerations (sc/<id>/act) by step."""
    from conftest import read_mcap

    from swarmhil.dashboards.run_config import run_config

    summary = json.loads((Path(run_dir) / "summary.json").read_text())
    truths, acts = {}, {}
    for topic, _lt, _pt, msg in read_mcap(Path(run_dir) / "run.mcap"):
        if topic == "truth":
            truths[int(msg.header.step)] = msg
        elif topic.startswith("sc/") and topic.endswith("/act"):
            acts.setdefault(msg.header.source, {})[int(msg.header.step)] = [msg.accel_mps2.x, msg.accel_mps2.y, msg.accel_mps2.z]
    steps = sorted(truths)
    assert steps == list(range(len(steps))), "truth has gaps"
    ids = [b.id for b in truths[0].bodies if b.kind == "spacecraft"]

    def rows(msg, field: str, kind: str = "spacecraft") -> list:
        return [[getattr(b, field).x, getattr(b, field).y, getattr(b, field).z] for b in msg.bodies if b.kind == kind]

    tr = [truths[k] for k in steps]
    out = {
        "summary": summary, "ids": ids,
        "t": np.array([m.header.t for m in tr]),
        "pos": np.array([rows(m, "position_m") for m in tr]),
        "vel": np.array([rows(m, "velocity_mps") for m in tr]),
        "accel": np.array([rows(m, "accel_cmd_mps2") for m in tr]),
        "target_pos": np.array([rows(m, "position_m", "target")[0] for m in tr]),
        "target_vel": np.array([rows(m, "velocity_mps", "target")[0] for m in tr]),
        "cmd": {sid: np.array([acts[sid][k] for k in sorted(acts[sid])]) for sid in acts},
        "config": run_config(run_dir),
    }
    return out


def metrics(run: dict) -> dict:
    """The figures of docs/paper003.md from recorded truth: the report section's own computation
    (missions/p003_surround/report.py surround_metrics) with the run's recorded configuration."""
    from swarmhil.missions.p003_surround.report import setup_from_config, surround_metrics

    su = setup_from_config(run.get("config"), run["ids"])
    return surround_metrics(run["t"], run["pos"], run["vel"], run["accel"][1:], run["target_pos"], su)


# --- the sensing kind -----------------------------------------------------------------------------
def test_sensing_kind_measures_relative_states_in_the_leaders_lvlh() -> None:
    from swarmhil.bus import swarmhil_pb2 as pb
    from swarmhil.bus.codec import measurements_to_dict
    from swarmhil.deploy.scenario import ScenarioError, load_scenario, plant_config
    from swarmhil.missions.p003_surround.contract import LEADER_REL_KEY, TARGET_REL_KEY
    from swarmhil.missions.p003_surround.fsw import sensing
    from swarmhil.plant.mission_world import MissionWorld
    from swarmhil.plant.sensing import SensingContext, make_sensing

    sc = plant_config(load_scenario(SCENARIO, sets=["sensing.params.position_noise_m=0.5",
                                                    "sensing.params.velocity_noise_mps=0.01"]))
    w = MissionWorld(sc)
    pos, vel = w.lvlh()
    ctx = SensingContext(0, 0.0, w.u_rad, w.ids, pos, vel, w.alive, w)

    def extras(kind: object) -> list[dict]:
        return [measurements_to_dict(kind.stimulus(ctx, j, pb.Header(step=0))) for j in range(len(w.ids))]

    a, b = extras(make_sensing("p003-relative", sc)), extras(make_sensing("p003-relative", sc))
    assert all(x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x) for x, y in zip(a, b))  # seeded
    assert set(a[0]) == {"p003.target_rel.position_m/tsat", "p003.target_rel.velocity_mps/tsat"}
    assert set(a[1]) == {"p003.leader_rel.position_m/lsat", "p003.leader_rel.velocity_mps/lsat"}
    target = sensing.read(a[0], TARGET_REL_KEY)
    assert np.abs(target.position_m - [900.0, 500.0, 500.0]).max() < 3.0  # 0.5 m noise, 6 sigma
    assert np.abs(target.velocity_mps - [5.0, 5.0, 5.0]).max() < 0.06
    me = sensing.read(a[3], LEADER_REL_KEY)  # ssat3: Table 1 row 3
    assert np.abs(me.position_m - [210.0, 30.0, 100.0]).max() < 3.0
    ideal = make_sensing("p003-relative", plant_config(load_scenario(SCENARIO)))
    got = measurements_to_dict(ideal.stimulus(ctx, 0, pb.Header(step=0)))
    assert np.allclose(got["p003.target_rel.position_m/tsat"], [900.0, 500.0, 500.0], atol=1e-6)
    with pytest.raises(ValueError, match="frame_origin"):
        make_sensing("p003-relative", plant_config(load_scenario(SCENARIO, sets=['plant.frame_origin="reference"'])))
    with pytest.raises(ScenarioError, match="sensing.params"):
        load_scenario(SCENARIO, sets=["sensing.params.bogus=1"])


# --- runs -----------------------------------------------------------------------------------------
def swarmhil_run(out: Path, *extra: str, env: dict[str, str] | None = None) -> dict:
    """`swarmhil run deploy/scenarios/surround-6.toml --out OUT [extra]` as its own process tree
    (`env`: variables added to this process's environment)."""
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIO), "--out", str(out), "--no-progress", *extra]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900,
                       env=None if env is None else {**os.environ, **env})
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return load_run(out)


def loop_prediction(duration_s: float):
    """The in-process closed loop of test_p003_closed_loop.py with the scenario's CT weights."""
    from test_p003_closed_loop import run_closed_loop

    from swarmhil.missions.p003_surround.contract import VARIANT_FAST_CT

    game = tomllib.loads(SCENARIO.read_text())["controller"]["params"]["game"]
    assert game == VARIANT_FAST_CT
    return run_closed_loop(duration_s=duration_s, game=dict(game))


def assert_stack_run(mp: dict, ip: dict, duration_s: float, loop_tol_m: float) -> dict:
    """Everything the brief asks of a stack run; returns the metrics of the multi-process run."""
    from swarmhil.missions.p003_surround.contract import FunnelParams, GameParams

    steps = int(round(duration_s / 0.1))
    s = mp["summary"]
    assert s["process_mode"] == "multi-process" and ip["summary"]["process_mode"] == "in-process"
    assert s["steps"] == steps and not s["dead_agents"] and not s["agent_faults"] and s["rejected_packets"] == 0
    assert set(s["exit_codes"].values()) == {0}
    # 1. same truth and commands, bit for bit, on Zenoh and on the in-memory bus
    for k in ("t", "pos", "vel", "accel", "target_pos", "target_vel"):
        assert np.array_equal(mp[k], ip[k]), k
    assert mp["cmd"].keys() == ip["cmd"].keys() and all(np.array_equal(mp["cmd"][i], ip["cmd"][i]) for i in mp["cmd"])
    m = metrics(mp)
    # 2. funnel: the TT error inside ±tan(k1 π/2) at every recorded step after t = 0
    assert np.all(np.abs(m["tt_err_m"][1:]) < m["funnel_m"][1:, None])
    # 3. as the in-process loop predicts (solve_ivp DOP853 vs the plant's RK steps; the filtered escape
    #    as 0.5 s means here vs continuous there)
    loop = loop_prediction(duration_s)
    assert np.abs(m["ct_pos_m"] - loop.ct_pos_err_m).max() < loop_tol_m
    assert np.abs(m["tt_err_m"] - loop.tt_err_m).max() < loop_tol_m
    # 4. no sphere intrusion (clearance to every sphere surface > the servicer's own safe radius r_i)
    assert m["min_clearance_m"] > GameParams().safe_radius_m
    assert m["min_pair_end_m"] > 2 * GameParams().safe_radius_m
    # 5. thrust limits from the truth, and the plant's limiter never cut a command (flight software did)
    assert m["leader_peak_n"] <= FunnelParams().max_thrust_n * (1 + 1e-12)
    assert m["sat_peak_n"] <= GameParams().max_thrust_n * (1 + 1e-12)
    for j, sid in enumerate(mp["ids"]):
        np.testing.assert_allclose(mp["accel"][1:, j], mp["cmd"][sid][:steps], rtol=1e-12, atol=1e-15)
    # 6. link: every packet broadcast to the six others, counted by the channel, none dropped
    tot = s["channel"]["totals"]
    assert tot["tx_messages"] == 7 * steps and tot["rx_messages"] == 6 * 7 * steps
    assert tot["tx_payload_bytes"] == steps * (41 + 6 * 50)
    assert sum(tot[f"dropped_{c}"] for c in ("range", "occulted", "lost", "queue")) == 0
    assert s["channel"]["forced_windows"] == 0 and s["channel"]["late_packets"] == 0
    m["loop_max_diff_m"] = float(max(np.abs(m["ct_pos_m"] - loop.ct_pos_err_m).max(),
                                     np.abs(m["tt_err_m"] - loop.tt_err_m).max()))
    return m


SHORT_S = 30.0


def test_surround6_flies_multi_process_over_zenoh(tmp_path: Path) -> None:
    """30 s of the scenario (≈ 20 s wall): multi-process over Zenoh and in-process, compared."""
    mp = swarmhil_run(tmp_path / "mp", "--duration", str(SHORT_S))
    ip = swarmhil_run(tmp_path / "ip", "--duration", str(SHORT_S), "--in-process")
    m = assert_stack_run(mp, ip, SHORT_S, loop_tol_m=0.01)
    # the first 30 s: the leader brakes the 1.15 km approach, servicers saturated at 20 N (Fig. 16)
    assert m["sat_saturated_frac"] > 0.5


OTHER_KERNELS = {"OPENBLAS_CORETYPE": "Sandybridge", "NPY_DISABLE_CPU_FEATURES": "X86_V3"}
"""Another CPU's kernels on this one: OpenBLAS's Sandy Bridge kernels and numpy without its AVX2/FMA
(x86-64-v3) loops. On the AVX2 machine of issue 24 this moves surround-6's truth by 1e-10 m in 30 s."""
FUNNEL_S = 30.0  # the worst TT ratio of the 300 s run is at 24.6 s (0.611)


def guard_margins(run: dict) -> tuple[float, float]:
    """max over the leader's steps of |q~_TL|/x1* and |q'_TL - q'_v|/x2*, where x* = tan(k e*) is the
    error at which funnel.sampled_limit's saturation starts (e* for the run's 0.1 s hold), recomputed
    from the truth (ideal sensing: the leader measured exactly this). Below 1: the guard never acted."""
    from swarmhil.missions.p003_surround.contract import FunnelParams, performance
    from swarmhil.missions.p003_surround.fsw.funnel import sampled_limit, virtual_velocity

    p, lead = FunnelParams(), run["ids"].index("lsat")
    dt = float(run["t"][1] - run["t"][0])
    q = run["target_pos"] - run["pos"][:, lead]
    v = run["target_vel"] - run["vel"][:, lead]
    m1 = m2 = 0.0
    for k, t in enumerate(run["t"][:-1]):
        k1, k2 = performance(t, p.mu1, p.a1_per_s), performance(t, p.mu2, p.a2_per_s)
        x1_star = np.tan(k1 * sampled_limit(k1, p.lambda1 * dt))
        x2_star = np.tan(k2 * sampled_limit(k2, p.lambda2 * dt / p.mass_kg))
        v_virtual, _ = virtual_velocity(q[k], t, p, dt)
        m1 = max(m1, float(np.abs(q[k] - np.asarray(p.q_des_m)).max() / x1_star))
        m2 = max(m2, float(np.abs(v[k] - v_virtual).max() / x2_star))
    return m1, m2


def test_surround6_stays_inside_the_funnel_on_both_kernel_sets(tmp_path: Path) -> None:
    """The first 30 s of surround-6 at its own 0.1 s step, in-process, with this CPU's kernels and with
    OTHER_KERNELS: the TT error stays inside ±tan(k1 π/2) with the worst ratio 0.611 (< 0.65, a
    margin of 0.35 to the bound), the discrete-time guard never acts (so the figures are the law's
    as written), and the two kernel sets agree to 1e-6 m (measured: 3e-11 m at 30 s, 5e-10 m at 300 s)."""
    runs = [swarmhil_run(tmp_path / name, "--duration", str(FUNNEL_S), "--in-process", env=env)
            for name, env in (("here", None), ("other", OTHER_KERNELS))]
    worst = []
    for run in runs:
        m = metrics(run)
        ratio = np.abs(m["tt_err_m"][1:]).max(axis=1) / m["funnel_m"][1:]
        assert 0.6 < ratio.max() < 0.65 and 20.0 < run["t"][1:][ratio.argmax()] < FUNNEL_S
        m1, m2 = guard_margins(run)
        assert m1 < 0.65 and m2 < 0.5, (m1, m2)
        worst.append((ratio.max(), m["tt_err_m"]))
    assert abs(worst[0][0] - worst[1][0]) < 1e-9
    assert np.abs(worst[0][1] - worst[1][1]).max() < 1e-6


@pytest.mark.system
def test_surround6_full_length_meets_the_papers_outcomes(tmp_path: Path) -> None:
    """The whole 300 s, multi-process and in-process: §5's outcomes from the recorded truth."""
    mp = swarmhil_run(tmp_path / "mp")
    ip = swarmhil_run(tmp_path / "ip", "--in-process")
    m = assert_stack_run(mp, ip, 300.0, loop_tol_m=0.05)
    assert m["ct_pos_end_m"] < 5.0 and m["ct_vel_end_mps"] < 0.5     # Fig. 13-14
    assert m["tt_err_end_m"] < 10.0 < m["funnel_end_m"]              # settled well inside the 47.5 m funnel


def report(run_dir: Path) -> None:
    run = load_run(run_dir)
    m = metrics(run)
    s = json.loads((Path(run_dir) / "summary.json").read_text())
    print({k: round(v, 4) for k, v in m.items() if not isinstance(v, np.ndarray)})
    ratio = np.abs(m["tt_err_m"][1:]).max(axis=1) / m["funnel_m"][1:]
    print(f"worst TT ratio {ratio.max():.7f} at {run['t'][1:][ratio.argmax()]:.1f} s; guard margins "
          "(|q~|/x1*, |q~' - q'_v|/x2*) %.3f %.3f" % guard_margins(run))
    print("channel totals", s["channel"]["totals"], "wall", round(s["wall_s"], 1), "s")


def compare(dir_a: Path, dir_b: Path) -> None:
    """Two runs of the scenario (e.g. the two kernel sets): largest truth differences, and of the TT
    error up to 30 s and over the whole run."""
    a, b = load_run(dir_a), load_run(dir_b)
    for k in ("pos", "vel", "accel", "target_pos"):
        print(k, "max |difference|", float(np.abs(a[k] - b[k]).max()))
    ta, tb = metrics(a)["tt_err_m"], metrics(b)["tt_err_m"]
    upto30 = a["t"] <= FUNNEL_S + 1e-9
    print("TT error max |difference|: first 30 s", float(np.abs(ta - tb)[upto30].max()),
          "whole run", float(np.abs(ta - tb).max()))


if __name__ == "__main__":  # RUN_DIR ... | --compare RUN_A RUN_B
    if sys.argv[1:2] == ["--compare"]:
        compare(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        for d in sys.argv[1:]:
            report(Path(d))
