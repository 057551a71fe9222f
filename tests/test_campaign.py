"""Issue 16: `swarmhil campaign` (deploy/campaign.py): seeded batch runs on Dask, one row per run,
resumable; `swarmhil sweep` on the same executor.

- a 4-seed, 1-hour sabatini-20 campaign on a Dask LocalCluster (127.0.0.1), in the batch mode
  (`--record truth`): each row equals the single in-process run of its seed made through the
  message path (one agent node per spacecraft, every message recorded): total dV and every metric
  (connectivity, closest approach), exactly; the Parquet and CSV tables hold the rows;
- a sweep on Dask gives each case the dV of the local process pool's run;
- a campaign killed (SIGKILL of its process group) after two finished seeds, run again on the same
  directory, runs only the other seeds and leaves the finished rows untouched;
- a failed run is a row with its error, and the others still finish.
"""
from __future__ import annotations

import csv
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, read_mcap, weakly_connected_by_hand
from system_tools import require_module

SCENARIO = str(SCENARIOS / "sabatini-20.toml")
DURATION_S = 600.0
CAMPAIGN_S = 3600.0


def _single_run(seed: int, out: Path) -> dict:
    """The run of one seed through the message path, with its metrics (`swarmhil run --in-process`
    then `swarmhil report`), as the campaign's flattened row columns."""
    from swarmhil.dashboards.report import write_report
    from swarmhil.deploy.campaign import summary_row
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(SCENARIO).with_overrides(seed=seed, duration_s=CAMPAIGN_S)
    run_in_process(sc, out, f"single-{seed}", record="all")
    write_report(out, figures=False)
    return summary_row(json.loads((out / "summary.json").read_text()))


def _connected_fraction(out: Path) -> float:
    """Share of truth steps whose camera visibility digraph is weakly connected, recounted with the
    plant's visibility rule and the test's own union-find."""
    import numpy as np

    from swarmhil.deploy.scenario import load_scenario
    from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

    cam = CameraGeometry(**load_scenario(SCENARIO).camera)
    conn = []
    for topic, _l, _p, m in read_mcap(out / "run.mcap"):
        if topic == "truth":
            pos = np.array([[b.position_m.x, b.position_m.y, b.position_m.z] for b in m.bodies])
            vis = visibility_matrix(pos, cam, np.array([b.alive for b in m.bodies]))
            conn.append(weakly_connected_by_hand(len(pos), zip(*np.nonzero(vis))))
    assert len(conn) == int(CAMPAIGN_S / 10.0) + 1
    return float(np.mean(conn))


def test_dask_campaign_rows_equal_single_runs(tmp_path: Path) -> None:
    require_module("dask.distributed")
    import pyarrow.parquet as pq

    from swarmhil.deploy.campaign import run_campaign

    seeds = [3, 4, 5, 6]
    res = run_campaign(SCENARIO, seeds, tmp_path / "c", duration_s=CAMPAIGN_S, executor="dask", jobs=2)
    assert sorted(res["ran"]) == seeds and res["skipped"] == []
    rows = {r["seed"]: r for r in res["rows"]}
    assert sorted(rows) == seeds
    for s in seeds:
        r = rows[s]
        assert r["status"] == "ok", r.get("error")
        assert r["steps"] == int(CAMPAIGN_S / 10.0) and r["batch.used"] is True
        single = _single_run(s, tmp_path / f"single{s}")
        compared = [k for k in single if k.startswith(("metrics.", "delta_v")) and not k.startswith("metrics.camera")]
        assert len(compared) > 30 and "metrics.closest_approach.all_pairs.distance_m" in compared
        assert {k: r[k] for k in compared} == {k: single[k] for k in compared}  # exactly: same truth
        # the connectivity the row holds, recounted from the single run's truth (the rows' equality
        # above says nothing if both paths compute it wrongly)
        assert r["metrics.connectivity.weakly_connected_fraction"] == pytest.approx(
            _connected_fraction(tmp_path / f"single{s}"), abs=1e-12)
    assert len({rows[s]["delta_v_total_mps"] for s in seeds}) == 4  # the seeds draw different swarms
    table = pq.read_table(tmp_path / "c" / "campaign.parquet").to_pylist()
    assert [t["seed"] for t in table] == seeds
    assert [t["delta_v_total_mps"] for t in table] == [rows[s]["delta_v_total_mps"] for s in seeds]
    with open(tmp_path / "c" / "campaign.csv") as f:
        csv_rows = list(csv.DictReader(f))
    assert [float(r["delta_v_total_mps"]) for r in csv_rows] == [rows[s]["delta_v_total_mps"] for s in seeds]
    report = (tmp_path / "c" / "report.md").read_text()
    assert "total dV [m/s] | 4 |" in report and "95 %" in report
    assert f"duration {CAMPAIGN_S:g} s;" in report, report.splitlines()[2]


def test_killed_campaign_resumes_with_the_remaining_seeds(tmp_path: Path) -> None:
    from swarmhil.deploy.campaign import row_path, run_campaign

    out = tmp_path / "c"
    seeds = [0, 1, 2, 3, 4]
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "campaign", SCENARIO, "--seeds", str(len(seeds)), "--first-seed", "0",
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


def test_a_campaign_of_an_edited_scenario_file_refuses_the_directory(tmp_path: Path) -> None:
    """The same path, other bytes: resuming would mix the rows of two scenarios (the file's sha256 is
    part of the campaign's record, as the faults file's is)."""
    from swarmhil.deploy.campaign import run_campaign

    scen = tmp_path / "s.toml"
    scen.write_text(Path(SCENARIO).read_text())
    out = tmp_path / "c"
    res = run_campaign(str(scen), [0], out, duration_s=20.0, executor="local", jobs=1, metrics=False)
    assert res["ran"] == [0]
    assert json.loads((out / "campaign.json").read_text())["scenario_sha256"] == hashlib.sha256(scen.read_bytes()).hexdigest()
    assert run_campaign(str(scen), [0], out, duration_s=20.0, executor="local", jobs=1, metrics=False)["skipped"] == [0]
    scen.write_text(scen.read_text().replace("k_ecc = 1.1", "k_ecc = 1.2"))
    with pytest.raises(ValueError, match="scenario_sha256"):
        run_campaign(str(scen), [0], out, duration_s=20.0, executor="local", jobs=1, metrics=False)


def test_failed_run_is_a_row(tmp_path: Path) -> None:
    from swarmhil.deploy.campaign import load_rows, run_seed

    bad = run_seed(SCENARIO, ("run.step_s=-1",), 7, str(tmp_path), DURATION_S, False)
    assert bad["status"] == "error" and bad["error"] and bad["seed"] == 7
    assert load_rows(tmp_path) == [json.loads(json.dumps(bad))]


def test_sweep_on_dask_equals_the_process_pool(tmp_path: Path) -> None:
    require_module("dask.distributed")
    from click.testing import CliRunner

    from swarmhil.deploy.cli import main

    dv = {}
    for ex in ("local", "dask"):
        out = tmp_path / ex
        res = CliRunner().invoke(main, ["sweep", SCENARIO, "--param", "controller.params.k_ecc", "--values", "1.1,1.5",
                                        "--duration", "300", "--out", str(out), "--jobs", "2", "--executor", ex,
                                        "--record", "truth", "--no-case-reports"])
        assert res.exit_code == 0, res.output
        cases = json.loads((out / "sweep.json").read_text())["cases"]
        dv[ex] = [c["delta_v_total_mps"] for c in cases]
    assert dv["local"] == dv["dask"] and dv["local"][0] != dv["local"][1]


def _worker_env() -> dict:
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS")}


def test_local_dask_workers_keep_glibc_malloc_defaults() -> None:
    """Dask's nanny would start each worker with MALLOC_TRIM_THRESHOLD_=65536, which pins glibc's
    mmap threshold at 128 KiB: every numpy temporary above it was an mmap + munmap, 408 k page
    faults per 24 h run (deploy/campaign.LOCAL_WORKER_ENV). The campaign's LocalCluster unsets it
    and keeps dask's one BLAS thread per worker."""
    require_module("dask.distributed")
    from swarmhil.deploy.campaign import execute

    saved = os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)  # the nanny runs in this process
    try:
        rows = execute(_worker_env, {0: ()}, executor="dask", jobs=1)
    finally:
        if saved is not None:
            os.environ["MALLOC_TRIM_THRESHOLD_"] = saved
    assert rows == [{"MALLOC_TRIM_THRESHOLD_": None, "OPENBLAS_NUM_THREADS": "1"}]
