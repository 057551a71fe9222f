"""Issue 16: `swarmhil campaign` (deploy/campaign.py): seeded batch runs on Dask, one row per run,
resumable.

- a 4-seed, 10-minute sabatini-20 campaign on a Dask LocalCluster (127.0.0.1): each row's total dV
  equals, exactly, the single in-process run of its seed; the Parquet and CSV tables hold the rows;
- a campaign killed (SIGKILL of its process group) after two finished seeds, run again on the same
  directory, runs only the other seeds and leaves the finished rows untouched;
- a failed run is a row with its error, and the others still finish.
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS

SCENARIO = str(SCENARIOS / "sabatini-20.toml")
DURATION_S = 600.0


def _single_run_dv(seed: int, out: Path) -> float:
    from deploy.launcher import run_in_process
    from deploy.scenario import load_scenario

    sc = load_scenario(SCENARIO).with_overrides(seed=seed, duration_s=DURATION_S)
    return run_in_process(sc, out, f"single-{seed}").summary["delta_v_total_mps"]


def test_dask_campaign_rows_equal_single_runs(tmp_path: Path) -> None:
    pytest.importorskip("dask.distributed")
    import pyarrow.parquet as pq

    from deploy.campaign import run_campaign

    seeds = [3, 4, 5, 6]
    res = run_campaign(SCENARIO, seeds, tmp_path / "c", duration_s=DURATION_S, executor="dask", jobs=2)
    assert sorted(res["ran"]) == seeds and res["skipped"] == []
    rows = {r["seed"]: r for r in res["rows"]}
    assert sorted(rows) == seeds
    for s in seeds:
        r = rows[s]
        assert r["status"] == "ok", r.get("error")
        assert r["steps"] == int(DURATION_S / 10.0)
        assert r["delta_v_total_mps"] == _single_run_dv(s, tmp_path / f"single{s}")  # exactly: same code, same seed
        assert 0.0 <= r["metrics.connectivity.weakly_connected_fraction"] <= 1.0
    assert len({rows[s]["delta_v_total_mps"] for s in seeds}) == 4  # the seeds draw different swarms
    table = pq.read_table(tmp_path / "c" / "campaign.parquet").to_pylist()
    assert [t["seed"] for t in table] == seeds
    assert [t["delta_v_total_mps"] for t in table] == [rows[s]["delta_v_total_mps"] for s in seeds]
    with open(tmp_path / "c" / "campaign.csv") as f:
        csv_rows = list(csv.DictReader(f))
    assert [float(r["delta_v_total_mps"]) for r in csv_rows] == [rows[s]["delta_v_total_mps"] for s in seeds]
    report = (tmp_path / "c" / "report.md").read_text()
    assert "total dV [m/s] | 4 |" in report and "95 %" in report


def test_killed_campaign_resumes_with_the_remaining_seeds(tmp_path: Path) -> None:
    from deploy.campaign import row_path, run_campaign

    out = tmp_path / "c"
    seeds = [0, 1, 2, 3, 4]
    cmd = [sys.executable, "-m", "deploy.cli", "campaign", SCENARIO, "--seeds", str(len(seeds)), "--first-seed", "0",
           "--duration", str(DURATION_S), "--executor", "local", "--jobs", "1", "--no-metrics", "--out", str(out)]
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        t_end = time.monotonic() + 300
        while len(list((out / "rows").glob("seed-*.json"))) < 2:
            assert p.poll() is None, "the campaign ended before it could be killed"
            assert time.monotonic() < t_end, "no two seeds finished in 300 s"
            time.sleep(0.05)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)  # the campaign and its pool worker: the group this test started
        p.wait(timeout=30)
    done = sorted(int(f.stem.split("-")[1]) for f in (out / "rows").glob("seed-*.json"))
    assert 2 <= len(done) < len(seeds)
    mtimes = {s: row_path(out, s).stat().st_mtime_ns for s in done}
    res = run_campaign(SCENARIO, seeds, out, duration_s=DURATION_S, executor="local", jobs=1, metrics=False)
    assert sorted(res["skipped"]) == done
    assert sorted(res["ran"]) == [s for s in seeds if s not in done]
    assert {s: row_path(out, s).stat().st_mtime_ns for s in done} == mtimes  # not run again
    assert [r["seed"] for r in res["rows"]] == seeds and all(r["status"] == "ok" for r in res["rows"])
    # a campaign with other parameters refuses the directory instead of mixing rows
    with pytest.raises(ValueError, match="duration_s"):
        run_campaign(SCENARIO, seeds, out, duration_s=1200.0, executor="local", jobs=1, metrics=False)


def test_failed_run_is_a_row(tmp_path: Path) -> None:
    from deploy.campaign import load_rows, run_seed

    bad = run_seed(SCENARIO, ("run.step_s=-1",), 7, str(tmp_path), DURATION_S, False)
    assert bad["status"] == "error" and bad["error"] and bad["seed"] == 7
    assert load_rows(tmp_path) == [json.loads(json.dumps(bad))]
