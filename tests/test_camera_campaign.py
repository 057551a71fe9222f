"""Issue 36: ideal sensing against the camera (exact blobs + rough navigation) through `swarmhil
campaign` and `swarmhil campaign-compare`, short, and the claims source that reads those campaigns.

Two seeds (1 and 2) for SPAN_S of simulated time: seed 1 stays whole under ideal sensing, seed 2
splits about 31 min in (so the headline holds one seed of the two). Checked against the two
campaigns' own tables, read independently: compare.json's paired split counts, its headline over
the seeds where ideal stays whole and its all-seeds block, the command's summary line, and that the
claims source (claims/camera_navigation.py) reads the finished campaigns without running them again
and gives every claim of the exact mode a number and its table row a verdict; and the issue's target in
short: where ideal stays whole, exact blobs + rough navigation stay whole at >= 97 % of the steps,
at most 1.3x ideal's ΔV (the 20-seed, 24 h figures are the study claims).

A synthetic set of paired rows checks the counting rule where the short runs cannot: splits on
one side only, both ways.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from conftest import ROOT, SCENARIOS

SPAN_S = 2100.0  # camera exact + rough in batch mode: a few seconds of CPU per run
FIRST_SEED, N_SEEDS = 1, 2
WCF = "metrics.connectivity.weakly_connected_fraction"
FS = "metrics.connectivity.first_split_t_s"
DV = "delta_v_total_mps"


def _cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    p = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=timeout)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> dict:
    d = tmp_path_factory.mktemp("cam36")
    procs = [subprocess.Popen([sys.executable, "-m", "swarmhil.deploy.cli", "campaign", str(SCENARIOS / f"{scen}.toml"),
                               "--seeds", str(N_SEEDS), "--first-seed", str(FIRST_SEED), "--duration", str(SPAN_S),
                               "--record", "truth", "--jobs", str(jobs), "--no-keep-recordings", "--out", str(d / label)],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for label, scen, jobs in (("exact", "sabatini-20-camera-exact", 2), ("ideal", "sabatini-20", 1))]
    try:
        for p in procs:  # both at once: the ideal runs take a few seconds beside the camera's
            out, _ = p.communicate(timeout=300)
            assert p.returncode == 0, out[-3000:]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    p = _cli("campaign-compare", str(d / "ideal"), str(d / "exact"), "--label", "ideal", "--label", "exact",
             "--out", str(d / "compare"))
    return {"dir": d, "stdout": p.stdout}


def _table(path) -> dict[int, dict]:  # type: ignore[no-untyped-def]
    import pyarrow.parquet as pq

    return {int(r["seed"]): r for r in pq.read_table(path).to_pylist()}


def _mean(xs: list[float]) -> float | None:
    return sum(xs) / len(xs) if xs else None


def test_compare_json_is_counted_from_the_two_campaigns(compared: dict) -> None:
    d = compared["dir"]
    ideal, exact = _table(d / "ideal" / "campaign.parquet"), _table(d / "exact" / "campaign.parquet")
    seeds = list(range(FIRST_SEED, FIRST_SEED + N_SEEDS))
    assert sorted(ideal) == sorted(exact) == seeds
    assert all(r["status"] == "ok" for r in (*ideal.values(), *exact.values()))
    doc = json.loads((d / "compare" / "compare.json").read_text())
    assert doc["base"]["label"] == "ideal" and doc["base"]["duration_s"] == SPAN_S
    assert list(doc["others"]) == ["exact"] and doc["at_least_pct"] == 97.0
    o = doc["others"]["exact"]
    assert o["seeds"] == seeds and o["n"] == N_SEEDS and o["same_initial_state"] is True
    assert (d / "compare" / "paired.parquet").is_file() and o["paired_table"] == str(d / "compare" / "paired.parquet")

    # whole: weakly connected at every step; the same as "no first split"
    def whole(r: dict) -> bool:
        w = r[WCF] == 1.0
        assert w == (r.get(FS) is None or (isinstance(r.get(FS), float) and math.isnan(r[FS]))), r["seed"]
        return w

    wb = {s: whole(ideal[s]) for s in seeds}
    wo = {s: whole(exact[s]) for s in seeds}
    assert o["base_whole"] == sum(wb.values())
    assert o["split_other_only"] == {"n": sum(wb[s] and not wo[s] for s in seeds),
                                     "seeds": [s for s in seeds if wb[s] and not wo[s]]}
    assert o["split_base_only"] == {"n": sum(wo[s] and not wb[s] for s in seeds),
                                    "seeds": [s for s in seeds if wo[s] and not wb[s]]}
    for block, chosen in (("headline", [s for s in seeds if wb[s]]), ("all_seeds", seeds)):
        b = o[block]
        assert b["seeds"] == chosen and b["n"] == len(chosen)
        conn = [100.0 * exact[s][WCF] for s in chosen]
        c = b["other_connectivity_pct"]
        assert c["n"] == len(chosen)
        if chosen:
            assert c["mean"] == pytest.approx(_mean(conn), abs=1e-9) and c["min"] == pytest.approx(min(conn), abs=1e-9)
            assert b["dv_ratio"]["mean"] == pytest.approx(_mean([exact[s][DV] / ideal[s][DV] for s in chosen]), rel=1e-12)
            assert b["diff_pp"]["mean"] == pytest.approx(
                _mean([100.0 * (exact[s][WCF] - ideal[s][WCF]) for s in chosen]), abs=1e-9)
            assert b["base_connectivity_pct"]["mean"] == pytest.approx(_mean([100.0 * ideal[s][WCF] for s in chosen]))
        else:
            assert c["mean"] is None and c["min"] is None
        assert b["other_at_least"] == sum(v >= 97.0 for v in conn)
        assert b["other_whole"] == sum(wo[s] for s in chosen)
    # the command's summary line says the same
    out = compared["stdout"]
    assert (f"split only under exact: {o['split_other_only']['n']}, only under ideal: {o['split_base_only']['n']}"
            in out), out
    assert f"where ideal stays whole ({o['headline']['n']} seeds)" in out
    md = (d / "compare" / "compare.md").read_text()
    assert "## Headline: the seeds where ideal stays whole" in md and "## All paired seeds" in md
    for s in seeds:
        assert f"\n| {s} | " in md


def test_the_claims_source_reads_the_campaigns_and_renders_its_row(compared: dict) -> None:
    from swarmhil.claims import camera_navigation as cam
    from swarmhil.claims.registry import registry
    from swarmhil.claims.render import render_table

    d = compared["dir"]
    before = {p: p.stat().st_mtime_ns for lab in ("ideal", "exact") for p in (d / lab / "rows").glob("seed-*.json")}
    assert len(before) == 2 * N_SEEDS
    res = cam.camera_campaign(range(FIRST_SEED, FIRST_SEED + N_SEEDS), SPAN_S, out=d, modes=cam.MODES[:1], jobs=1)
    assert {p: p.stat().st_mtime_ns for p in before} == before  # read, not run again
    doc = json.loads((d / "compare-exact" / "compare.json").read_text())
    assert res == cam.campaign_result(doc)
    assert res["seeds"] == N_SEEDS and res["exact.split_only"] == doc["others"]["exact"]["split_other_only"]["n"]
    reg = registry()
    mine = [c for c in reg.claims.values() if c.source == cam.source_of("exact")]
    assert mine and reg.sources[cam.source_of("exact")].tier == "study"
    values = {}
    for c in mine:
        if "filter" in c.id:
            continue
        v = c.compute(res)
        if c.id.endswith(("head-min", "head-mean")) and res["exact.head_n"] == 0:
            assert v == "none"
            continue
        assert isinstance(v, (int, float)) and math.isfinite(v), (c.id, v)
        values[c.id] = v
    table = reg.tables["camera-campaign"]
    row = render_table(table, reg.claims, values).splitlines()[2]
    assert row.startswith("| exact blobs") and "(not recorded)" not in row
    assert "| met" in row or "| not met: " in row, row
    assert cam.commands("runs/x", range(20), 86400.0)[0].startswith(
        "swarmhil campaign deploy/scenarios/sabatini-20.toml --seeds 20 --first-seed 0 --duration 86400 --record truth")


def test_split_counts_and_headline_of_synthetic_pairs() -> None:
    from swarmhil.deploy.campaign_compare import compare_aggregates

    def row(seed: int, base: float, other: float, dvb: float = 2.0, dvo: float = 2.4) -> dict:
        return {"seed": seed, f"base.{WCF}": base, f"other.{WCF}": other, f"pp.{WCF}": 100.0 * (other - base),
                "ratio.delta_v_total_mps": dvo / dvb, "base.whole": base == 1.0, "other.whole": other == 1.0}

    rows = [row(0, 1.0, 1.0), row(1, 1.0, 0.96), row(2, 1.0, 0.98), row(3, 0.7, 1.0), row(4, 0.5, 0.6, dvo=3.0)]
    a = compare_aggregates(rows, 97.0)
    assert a["split_other_only"] == {"n": 2, "seeds": [1, 2]} and a["split_base_only"] == {"n": 1, "seeds": [3]}
    h = a["headline"]
    assert h["seeds"] == [0, 1, 2] and h["other_at_least"] == 2 and h["other_whole"] == 1
    assert h["other_connectivity_pct"]["min"] == pytest.approx(96.0) and h["other_connectivity_pct"]["mean"] == pytest.approx(98.0)
    assert h["dv_ratio"]["mean"] == pytest.approx(1.2)
    al = a["all_seeds"]
    assert al["n"] == 5 and al["other_connectivity_pct"]["min"] == pytest.approx(60.0) and al["other_at_least"] == 3
    assert al["dv_ratio"]["mean"] == pytest.approx((4 * 1.2 + 1.5) / 5)
    assert a["base_whole"] == 3
    none = compare_aggregates([row(0, 0.9, 1.0)], 97.0)["headline"]
    assert none["n"] == 0 and none["other_connectivity_pct"]["mean"] is None and none["other_at_least"] == 0


def test_exact_blobs_keep_the_swarm_where_ideal_sensing_does(compared: dict) -> None:
    """The short version of the issue-36 target, on the same runs: with the paper's imaging assumption
    (exact blobs) and the rough navigator, every seed that stays whole under ideal sensing over the
    span stays whole at >= 97 % of the steps, and the ΔV is within 1.3x of ideal's on every seed
    (the face-on range and the plain difference, before the fix, spent 1.4x on seed 0 in 6 h)."""
    d = compared["dir"]
    ideal, exact = _table(d / "ideal" / "campaign.parquet"), _table(d / "exact" / "campaign.parquet")
    whole = [s for s in ideal if ideal[s][WCF] == 1.0]
    assert whole, "no seed stays whole under ideal sensing over the span: the check would test nothing"
    assert all(exact[s][WCF] >= 0.97 for s in whole), {s: exact[s][WCF] for s in whole}
    assert all(exact[s][DV] <= 1.3 * ideal[s][DV] for s in ideal), {s: exact[s][DV] / ideal[s][DV] for s in ideal}
