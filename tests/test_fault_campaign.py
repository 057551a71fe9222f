"""Issue 27: fault campaigns, `swarmhil campaign SCENARIO --faults FILE [--baseline]`
(deploy/fault_draws.py, deploy/campaign.py).

- the draws are a pure function of the file and the seed, inside their ranges, and one draw's
  probability does not shift the others' values (each draw takes its numbers whether it hits or not);
- a bad faults file is one line naming the file, the table and the field (exit 2 from the CLI);
- a 3-seed campaign on Dask with --baseline: each faulted row equals the single in-process run of
  a scenario file with the drawn faults written into it as `[[fault]]` tables (exactly), each
  baseline row the run without them, a stuck-off thruster gives no ΔV in its window (from the
  recording), and the report's per-kind counts are the rows' faults;
- the recovery fraction judges only faults it can judge (a run that ends before the window, not
  yet whole, says nothing).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS, read_mcap
from system_tools import require_module

SCENARIO = SCENARIOS / "sabatini-20.toml"
THRUSTERS = ROOT / "deploy" / "fault_campaigns" / "thrusters.toml"
IDS = [f"sc{i:02d}" for i in range(1, 21)]


def _draws(tmp_path: Path, text: str):
    from swarmhil.deploy.fault_draws import load_fault_draws

    p = tmp_path / "f.toml"
    p.write_text(text)
    return load_fault_draws(p, IDS)


def test_draws_are_seeded_inside_their_ranges_and_independent_of_each_others_hits(tmp_path: Path) -> None:
    from swarmhil.deploy.fault_draws import draw_faults

    text = """
[[draw]]
kind = "thruster_efficiency"
probability = {p}
targets = 3
pool = ["sc01", "sc02", "sc03", "sc04", "sc05"]
start_s = [100.0, 200.0]
duration_s = 50.0
[draw.params]
factor = [0.2, 0.4]

[[draw]]
kind = "link_partition"
groups = 3
start_s = 300.0
duration_s = [10.0, 20.0]

[[draw]]
kind = "thruster_stuck_on"
start_s = 0.0
duration_s = 10.0
[draw.params]
accel_mps2 = [0.0, 1e-4, 0.0]
"""
    always, never = _draws(tmp_path, text.format(p=1.0)), _draws(tmp_path, text.format(p=0.0))
    runs = [draw_faults(always, IDS, s) for s in range(40)]
    assert runs[7] == draw_faults(always, IDS, 7)  # a pure function of file and seed
    assert len({json.dumps(r) for r in runs}) == 40
    for r in runs:
        eff, part, on = r
        assert eff["name"] == "draw0-thruster_efficiency" and 100.0 <= eff["start_s"] <= 200.0
        assert eff["duration_s"] == 50.0 and 0.2 <= eff["factor"] <= 0.4
        assert len(eff["targets"]) == 3 and set(eff["targets"]) <= {"sc01", "sc02", "sc03", "sc04", "sc05"}
        flat = [s for g in part["groups"] for s in g]
        assert len(part["groups"]) == 3 and sorted(flat) == IDS and {len(g) for g in part["groups"]} <= {6, 7}
        assert 10.0 <= part["duration_s"] <= 20.0 and on["accel_mps2"] == [0.0, 1e-4, 0.0]  # a vector stays
    # with the first draw never hitting, the other two are the same faults, seed by seed
    assert [draw_faults(never, IDS, s) for s in range(40)] == [r[1:] for r in runs]
    half = _draws(tmp_path, text.format(p=0.5))
    hits = sum(len(draw_faults(half, IDS, s)) == 3 for s in range(400))
    assert 160 < hits < 240  # binomial(400, 0.5): mean 200, sd 10


@pytest.mark.parametrize("body, message", [
    ('[[draw]]\nkind = "thruster_jammed"\nstart_s = 0.0\nduration_s = 1.0',
     r"f.toml: \[\[draw\]\]\[0\].kind Value error, is not a known fault kind"),
    ('[[draw]]\nkind = "thruster_stuck_off"\nstart_s = [5.0, 1.0]\nduration_s = 1.0',
     r"\[\[draw\]\]\[0\].start_s .*0 <= low <= high"),
    ('[[draw]]\nkind = "thruster_efficiency"\nstart_s = 0.0\nduration_s = 1.0\n[draw.params]\nangle_deg = 3.0',
     r"\[\[draw\]\]\[0\] .*params.angle_deg is not a field of thruster_efficiency"),
    ('[[draw]]\nkind = "thruster_stuck_off"\npool = ["sc99"]\nstart_s = 0.0\nduration_s = 1.0',
     r"\[\[draw\]\]\[0\].pool names unknown spacecraft id 'sc99'"),
    ('[[draw]]\nkind = "thruster_stuck_off"\ntargets = 3\npool = ["sc01"]\nstart_s = 0.0\nduration_s = 1.0',
     r"\[\[draw\]\]\[0\] needs 3 spacecraft from a pool of 1"),
    ('[[draw]]\nkind = "thruster_stuck_off"\nstart_s = 0.0', r"\[\[draw\]\]\[0\].duration_s Field required"),
    ('[recovery]\nhold_s = 10.0', r"f.toml: .draw Field required"),
    ('[[draw]]\nkind = "thruster_stuck_off"\nstart_s = 0.0\nduration_s = 1.0\n[recovery]\nwithin_s = 10.0',
     r"f.toml: .recovery.within_s is not a known field"),
    ('[[draw]\n', r"f.toml: not TOML"),
])
def test_bad_faults_files_are_one_precise_line(tmp_path: Path, body: str, message: str) -> None:
    from swarmhil.deploy.fault_draws import FaultDrawError

    with pytest.raises(FaultDrawError, match=message) as info:
        _draws(tmp_path, body)
    assert "\n" not in str(info.value)


def test_cli_refuses_a_bad_faults_file_and_a_baseline_without_faults(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[[draw]]\nkind = "thruster_stuck_off"\nstart_s = 0.0\nduration_s = 0.0\n')
    cli = [sys.executable, "-m", "swarmhil.deploy.cli", "campaign", str(SCENARIO), "--seeds", "2", "--out", str(tmp_path / "c")]
    for extra, why in ((["--faults", str(bad)], "[[fault]][0].duration_s Input should be greater than 0"),
                       (["--baseline"], "--baseline needs --faults")):
        r = subprocess.run([*cli, *extra], capture_output=True, text=True, cwd=ROOT, timeout=120)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and why in r.stderr, r.stderr
        assert not (tmp_path / "c" / "campaign.json").exists()  # nothing started


def test_fault_outcomes_are_counted_apart_and_never_split_is_not_recovered() -> None:
    from swarmhil.deploy.campaign import _fault_lines, fault_stats

    def fault(outcome, kind="k", **extra):
        return {"kind": kind, "outcome": outcome, "hold_s": 5400.0, "delta_v_in_window_mps": 0.1,
                "time_to_reconnect_s": 100.0 if outcome == "split and recovered" else None, **extra}

    faults = [fault("never split"), fault("never split"), fault("split and recovered"), fault("not recovered"),
              fault("not judged"),
              # a link fault is judged on its link graph: never split on the cameras, split and lost on the link
              fault("never split", kind="link_partition", link_outcome="not recovered"),
              fault("never split", kind="link_partition")]  # no link deliveries recorded: not judged
    rows = [{"status": "ok", "faults": json.dumps(faults)}, {"status": "error", "faults": json.dumps(faults)}]
    stats = fault_stats(rows)
    s = stats["k"]
    assert (s["drawn"], s["judged"], s["not judged"]) == (5, 4, 1)
    assert [s[o]["n"] for o in ("never split", "split and recovered", "not recovered")] == [2, 1, 1]
    assert s["split and recovered"]["fraction"] == 0.25 and s["time_to_reconnect_s"]["mean"] == 100.0
    from scipy.stats import binomtest

    ci = binomtest(2, 4).proportion_ci(0.95, "wilson")
    assert (s["never split"]["ci95_low"], s["never split"]["ci95_high"]) == (ci.low, ci.high)
    link = stats["link_partition"]
    assert (link["judged"], link["not recovered"]["n"], link["never split"]["n"]) == (1, 1, 0)
    lines = "\n".join(_fault_lines(rows, {"faults": {"file": "f.toml"}}, lambda v: "" if v is None else f"{v:.3g}"))
    assert "| k | 5 | 4 | 2 (0.5 [0.150, 0.850]) | 1 (0.25 [0.046, 0.699]) | 1 (0.25 [0.046, 0.699]) |" in lines, lines
    assert "staying so for 5.4e+03 s" in lines


def test_dask_fault_campaign_rows_equal_single_runs_of_the_drawn_scenario(tmp_path: Path) -> None:
    require_module("dask.distributed")
    import tomllib

    from swarmhil.deploy.campaign import run_campaign
    from swarmhil.deploy.fault_draws import draw_faults, load_fault_draws
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    duration, seeds = 5400.0, [0, 1, 2]
    res = run_campaign(str(SCENARIO), seeds, tmp_path / "c", duration_s=duration, executor="dask", jobs=2,
                       faults=THRUSTERS, baseline=True)
    rows = {r["seed"]: r for r in res["rows"]}
    base = {r["seed"]: r for r in (json.loads(p.read_text()) for p in (tmp_path / "c" / "baseline" / "rows").glob("*.json"))}
    assert sorted(rows) == sorted(base) == seeds
    draws = load_fault_draws(THRUSTERS, IDS)
    kinds: dict[str, int] = {}
    thrusting: list[bool] = []
    for s in seeds:
        r = rows[s]
        assert r["status"] == "ok" and base[s]["status"] == "ok", (r.get("error"), base[s].get("error"))
        drawn = draw_faults(draws, IDS, s)
        got = json.loads(r["faults"])
        assert [{k: f[k] for k in d} for f, d in zip(got, drawn)] == drawn and r["faults_n"] == len(drawn)
        for f in got:
            kinds[f["kind"]] = kinds.get(f["kind"], 0) + 1
            assert f["time_to_reconnect_s"] is None or f["time_to_reconnect_s"] >= 0.0
            assert f["outcome"] in ("never split", "split and recovered", "not recovered", "not judged")
            assert f["recovered"] is (True if f["outcome"] == "split and recovered" else
                                      False if f["outcome"] == "not recovered" else None)
        # the same run by hand: the scenario file with the drawn faults written in, flown in-process
        doc = tomllib.loads(SCENARIO.read_text())
        text = SCENARIO.read_text() + "".join(
            "\n[[fault]]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in f.items()) for f in drawn)
        path = tmp_path / f"drawn{s}.toml"
        path.write_text(text)
        assert tomllib.loads(text)["fault"] and doc.get("fault") is None
        single = run_in_process(load_scenario(path).with_overrides(seed=s, duration_s=duration), tmp_path / f"s{s}",
                                f"s{s}", progress=False)
        assert single.summary["delta_v_total_mps"] == r["delta_v_total_mps"]  # exactly: the same truth
        assert r["delta_v_extra_mps"] == r["delta_v_total_mps"] - base[s]["delta_v_total_mps"]
        for f in drawn:  # a stuck-off thruster: no ΔV of its spacecraft inside the window (recorded truth)
            if f["kind"] == "thruster_stuck_off":
                (sid,) = f["targets"]
                truth = [m for t, _l, _p, m in read_mcap(tmp_path / f"s{s}" / "run.mcap") if t == "truth"]
                dv = np.array([[b.delta_v_mps for b in m.bodies if b.id == sid][0] for m in truth])
                t = np.array([m.header.t for m in truth])
                inside = (t > f["start_s"] + 10.0) & (t < f["start_s"] + f["duration_s"])
                assert inside.sum() > 50 and np.ptp(dv[inside]) == 0.0
                thrusting.append(bool(np.ptp(dv) > 0.0))  # it spends ΔV outside the window
    assert len(thrusting) >= 2 and any(thrusting), thrusting  # else "no ΔV in the window" proves nothing
    assert len({r["delta_v_extra_mps"] for r in rows.values()}) == 3
    report = (tmp_path / "c" / "report.md").read_text()
    for kind, n in kinds.items():
        assert f"| {kind} | {n} |" in report, report
    assert "Extra ΔV over the same seed without faults (OUT/baseline)" in report
    assert "<h2>Faults (drawn from" in (tmp_path / "c" / "report.html").read_text()


def test_a_baseline_judges_the_same_windows_without_the_fault(tmp_path: Path) -> None:
    """with_baseline_outcomes judges each drawn fault's window on the baseline run's series, and the
    report puts those counts on a row of their own under the faulted ones."""
    from swarmhil.dashboards.run_metrics import SERIES
    from swarmhil.dashboards.sections.faults import with_baseline_outcomes
    from swarmhil.deploy.campaign import _fault_lines, fault_stats

    t = np.arange(0.0, 2000.0, 10.0)
    ncomp = np.where((t >= 500.0) & (t < 700.0), 2, 1)        # the swarm splits on its own over [500, 700) s
    np.savez(tmp_path / SERIES, t_s=t, delta_v_total_mps=np.zeros(t.size), n_components=ncomp)
    drawn = [{"kind": "k", "start_s": 100.0, "end_s": 200.0, "hold_s": 300.0, "outcome": "not recovered"},
             {"kind": "k", "start_s": 450.0, "end_s": 600.0, "hold_s": 300.0, "outcome": "not recovered"},
             {"kind": "link_partition", "start_s": 100.0, "end_s": 200.0, "hold_s": 300.0}]
    got = with_baseline_outcomes(drawn, tmp_path)
    assert [f["baseline_outcome"] for f in got] == ["split and recovered", "split and recovered", "not judged"]
    assert [f["baseline_outcome"] for f in with_baseline_outcomes(drawn, tmp_path / "none")] == ["not judged"] * 3
    rows = [{"status": "ok", "faults": json.dumps(got[:2])}]
    assert fault_stats(rows)["k"]["baseline"] == {"never split": 0, "split and recovered": 2, "not recovered": 0,
                                                   "not judged": 0}
    lines = _fault_lines(rows, {"faults": {"file": "f.toml"}}, lambda v: "" if v is None else f"{v:.3g}")
    assert "| k, same windows without faults | 2 | 2 | 0 | 2 | 0 | | |" in lines, lines
