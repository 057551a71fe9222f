"""`swarmhil report` of a paper 003 run: the "p003-surround" section (missions/p003_surround/report.py).

A 20 s in-process run of deploy/scenarios/surround-6.toml, then `python -m swarmhil.deploy.cli report RUN`
as its own process; the section's metrics in summary.json must equal a recomputation written out here
from the MCAP (tests/conftest.py read_mcap, the scenario file for the structure, masses and limits),
and its PNGs must exist and be on the report page.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
for p in (ROOT, ROOT / "tests"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from test_p003_stack import SCENARIO, swarmhil_run  # noqa: E402

DURATION_S = 20.0
FIGURES = ("p003_tt_funnel.png", "p003_ct_errors.png", "p003_paths3d.png", "p003_thrust.png")


def recompute(run: dict) -> dict:
    """The section's headline metrics from the recorded truth, written out independently."""
    from swarmhil.missions.p003_surround.contract import SLOT_OFFSETS_M

    doc = tomllib.loads(SCENARIO.read_text())
    crafts = {s["id"]: s for s in doc["spacecraft"]}
    shape = doc["body"][0]["shape"]
    centres, radii = np.asarray(shape["centers_m"]), np.asarray(shape["radii_m"])
    ids, t, pos, vel = run["ids"], run["t"], run["pos"], run["vel"]
    L = ids.index("lsat")
    sats = [i for i, s in enumerate(ids) if crafts[s]["role"] == "servicer"]
    q_des = np.array([400.0, 0.0, 0.0])  # §5 q_TL,d (the scenario's funnel table keeps the default)
    mu, a = 0.1, 5e-5                     # §5 mu1, a1
    err = run["target_pos"] - pos[:, L] - q_des
    ratio = [np.abs(err[k]).max() / math.tan(((1 - mu) * math.exp(-a * t[k]) + mu) * math.pi / 2)
             for k in range(1, len(t))]
    out = {"worst_tt_ratio": max(ratio), "tt_err_end_m": float(np.abs(err[-1]).max()), "ct_pos_end_m": {},
           "ct_vel_end_mps": {}, "min_clearance_m": math.inf, "min_servicer_distance_m": math.inf}
    for i in sats:
        sid = ids[i]
        slot = q_des + SLOT_OFFSETS_M[int(sid[-1]) - 1]
        out["ct_pos_end_m"][sid] = float(np.linalg.norm(pos[-1, i] - pos[-1, L] - slot))
        out["ct_vel_end_mps"][sid] = float(np.linalg.norm(vel[-1, i] - vel[-1, L]))
        for k in range(len(t)):
            d = np.linalg.norm(pos[k, i] - (run["target_pos"][k] + centres), axis=1) - radii
            out["min_clearance_m"] = min(out["min_clearance_m"], float(d.min()))
            for j in sats:
                if j > i:
                    out["min_servicer_distance_m"] = min(out["min_servicer_distance_m"],
                                                         float(np.linalg.norm(pos[k, i] - pos[k, j])))
    acc = run["accel"][1:]  # truth accel_cmd_mps2 of step k: applied over the step that ended at t_k
    out["peak_thrust_n"] = {
        "leader": float(np.linalg.norm(acc[:, L], axis=1).max() * crafts["lsat"]["mass_kg"]),
        "servicer": max(float(np.linalg.norm(acc[:, i], axis=1).max() * crafts[ids[i]]["mass_kg"]) for i in sats)}
    out["thrust_limit_n"] = {"leader": crafts["lsat"]["max_force_n"],
                             "servicer": max(crafts[ids[i]]["max_force_n"] for i in sats)}
    # dV: the plant's cumulative |a| dt, summed here from the commands
    dt = np.diff(t)
    dv = {ids[i]: float((np.linalg.norm(acc[:, i], axis=1) * dt).sum()) for i in sats}
    out["mean_dv_servicer_mps"] = float(np.mean(list(dv.values())))
    return out


def test_report_has_the_surround_section(tmp_path: Path) -> None:
    run_dir = tmp_path / "s6"
    run = swarmhil_run(run_dir, "--duration", str(DURATION_S), "--in-process")
    p = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "report", str(run_dir), "--no-vector"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    got = json.loads((run_dir / "summary.json").read_text())["metrics"]["p003-surround"]
    want = recompute(run)

    assert got["leader"] == "lsat" and got["target"] == "tsat"
    assert got["servicers"] == [f"ssat{i}" for i in range(1, 7)]
    assert got["window_s"] == [0.0, DURATION_S]
    for k in ("worst_tt_ratio", "tt_err_end_m", "min_clearance_m", "min_servicer_distance_m", "mean_dv_servicer_mps"):
        assert math.isclose(got[k], want[k], rel_tol=1e-9, abs_tol=1e-9), (k, got[k], want[k])
    for k in ("ct_pos_end_m", "ct_vel_end_mps", "peak_thrust_n", "thrust_limit_n"):
        assert got[k].keys() == want[k].keys(), k
        for n in want[k]:
            assert math.isclose(got[k][n], want[k][n], rel_tol=1e-9, abs_tol=1e-9), (k, n, got[k][n], want[k][n])
    assert got["left_funnel"] is False and 0 < got["worst_tt_ratio"] < 1
    assert got["peak_thrust_n"]["servicer"] <= got["thrust_limit_n"]["servicer"] * (1 + 1e-12)
    assert got["peak_thrust_n"]["leader"] <= got["thrust_limit_n"]["leader"] * (1 + 1e-12)

    page = (run_dir / "report" / "index.html").read_text()
    assert "Paper 003: surrounding an escaping target" in page
    # issue 25: the overview is mission-neutral, paper 002's metrics are not in it (nor its section)
    overview = page.split("<h2", 1)[0]
    for word in ("along-track to closest visible", "orbit-minimum a(|dl|-2|de|)", "radial a|de|", "parallelism",
                 "always weakly connected"):
        assert word not in page, word
    assert "dV per spacecraft" in overview and "link traffic" in overview and "p002-swarm" not in page
    met = json.loads((run_dir / "summary.json").read_text())["metrics"]  # paper 002's metrics hook did not run
    assert not {"connectivity", "closest_visible_steady", "visible_pairs_parallelism_steady"} & set(met)
    assert "visible_pairs" not in met["closest_approach"] and "all_pairs" in met["closest_approach"]
    for f in FIGURES:
        png = run_dir / "report" / f
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000, f
        assert f'src="{f}"' in page, f


def test_faults_section_gives_the_funnel_ratio_around_a_leader_fault(tmp_path: Path) -> None:
    """surround-6 for 20 s with the leader's thrusters stuck off over [5, 15) s: the faults section
    gives paper 003's error metric (the leader's TT error over the funnel bound, registered by
    missions/p003_surround/report.py) around the window, equal to the ratio recounted here from the
    recorded truth (recompute's formula)."""
    from swarmhil.dashboards.report import write_report
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    path = tmp_path / "s6f.toml"
    path.write_text(SCENARIO.read_text() + '\n[[fault]]\nname = "lead-off"\nkind = "thruster_stuck_off"\n'
                    'targets = ["lsat"]\nstart_s = 5.0\nend_s = 15.0\n')
    out = tmp_path / "run"
    run_in_process(load_scenario(path).with_overrides(duration_s=DURATION_S), out, "s6f", progress=False)
    write_report(out, export=())
    rec = json.loads((out / "summary.json").read_text())["metrics"]["faults"]["lead-off"]
    t, err = [], []
    from conftest import read_mcap

    for topic, _l, _p, m in read_mcap(out / "run.mcap"):
        if topic == "truth":
            pos = {b.id: np.array([b.position_m.x, b.position_m.y, b.position_m.z]) for b in m.bodies}
            t.append(m.header.t)
            err.append(pos["tsat"] - pos["lsat"] - np.array([400.0, 0.0, 0.0]))
    t = np.array(t)
    ratio = np.array([np.abs(err[k]).max() / math.tan(((1 - 0.1) * math.exp(-5e-5 * t[k]) + 0.1) * math.pi / 2)
                      for k in range(1, len(t))])
    t1 = t[1:]
    inside = (t1 >= 5.0 - 1e-9) & (t1 < 15.0 - 1e-9)
    key = "leader's TT error over the funnel bound {} [ratio]"
    assert math.isclose(rec[key.format("max_in_window")], ratio[inside].max(), rel_tol=1e-9)
    assert math.isclose(rec[key.format("at_start")], ratio[inside][0], rel_tol=1e-9)
    assert math.isclose(rec[key.format("at_run_end")], ratio[-1], rel_tol=1e-9)
