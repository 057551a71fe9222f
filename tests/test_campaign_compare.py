"""Issue 16: `swarmhil campaign-compare` (deploy/campaign_compare.py), the paired table of two
campaigns over the same seeds.

Two real 2-seed, 600 s sabatini-20 campaigns (batch mode): ideal sensing, and the same scenario with
noisy relative sensing (`--set sensing.roe_noise_fraction=0.3`: another sensing, the same
dispersion). Checked against the two campaigns' own Parquet tables, read independently:

- every pair started from the same initial state, and a campaign of another dispersion does not;
- each seed's difference in per-step weak connectivity (percentage points), dV ratio and
  closest-approach difference; the mean over the seeds and its Student-t interval;
- the connectivity per time window, weighted by its steps, gives the run's whole fraction;
- the command line: campaigns of different durations are refused in one line, exit 2.
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS

SCENARIO = str(SCENARIOS / "sabatini-20.toml")
DURATION_S = 600.0
SEEDS = [0, 1]


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory: pytest.TempPathFactory) -> dict:
    from swarmhil.deploy.campaign import run_campaign

    d = tmp_path_factory.mktemp("pairs")
    out = {}
    for name, sets, seeds, dur in (("ideal", (), SEEDS, DURATION_S),
                                   ("noisy", ("sensing.roe_noise_fraction=0.3",), SEEDS, DURATION_S),
                                   ("spread", ("dispersion.along_track_spacing_m=210.0",), SEEDS[:1], DURATION_S),
                                   ("short", (), SEEDS[:1], 300.0)):
        res = run_campaign(SCENARIO, seeds, d / name, sets=sets, duration_s=dur, executor="local", jobs=1)
        assert all(r["status"] == "ok" for r in res["rows"]), res["rows"]
        out[name] = d / name
    return out


def test_paired_table_equals_the_two_campaigns(campaigns: dict, tmp_path) -> None:
    import pyarrow.parquet as pq
    from scipy.stats import t as student_t

    from swarmhil.deploy.campaign_compare import WCF, write_paired

    res = write_paired(campaigns["ideal"], campaigns["noisy"], tmp_path / "p", ("ideal", "noisy"), 2.0, 300.0)
    a = pq.read_table(campaigns["ideal"] / "campaign.parquet").to_pandas().set_index("seed")
    b = pq.read_table(campaigns["noisy"] / "campaign.parquet").to_pandas().set_index("seed")
    p = pq.read_table(tmp_path / "p" / "paired.parquet").to_pandas().set_index("seed")
    assert sorted(p.index) == SEEDS
    ca = "metrics.closest_approach.all_pairs.distance_m"
    for s in SEEDS:
        assert bool(p.loc[s, "same_initial_state"]) is True
        assert p.loc[s, f"pp.{WCF}"] == pytest.approx(100.0 * (b.loc[s, WCF] - a.loc[s, WCF]), abs=1e-12)
        assert p.loc[s, "ratio.delta_v_total_mps"] == pytest.approx(
            b.loc[s, "delta_v_total_mps"] / a.loc[s, "delta_v_total_mps"], rel=1e-12)
        assert p.loc[s, f"diff.{ca}"] == pytest.approx(b.loc[s, ca] - a.loc[s, ca], abs=1e-9)
        # 61 steps: t = 0..290 s in the first window (30), 300..600 s in the second (31)
        for side, tab in (("base", a), ("other", b)):
            w = 30 * p.loc[s, f"window00.{side}"] + 31 * p.loc[s, f"window01.{side}"]
            assert w / 61 == pytest.approx(tab.loc[s, WCF], abs=1e-12)
    # the two sensings flew differently (else this test would compare a campaign with itself)
    assert not np.allclose(p["ratio.delta_v_total_mps"], 1.0)
    d = 100.0 * (b.loc[SEEDS, WCF].to_numpy() - a.loc[SEEDS, WCF].to_numpy())
    st = res["stats"]["metrics"][WCF]
    h = student_t.ppf(0.975, len(d) - 1) * np.std(d, ddof=1) / np.sqrt(len(d))
    assert st["mean"] == pytest.approx(d.mean(), abs=1e-12)
    assert st["ci95_low"] == pytest.approx(d.mean() - h, abs=1e-9)
    assert res["stats"]["seeds_within"] == int(np.sum(np.abs(d) <= 2.0))
    md = (tmp_path / "p" / "paired.md").read_text()
    assert "same initial state in every pair: yes" in md and "| 0 | yes |" in md


def test_other_dispersion_is_not_the_same_start(campaigns: dict, tmp_path) -> None:
    from swarmhil.deploy.campaign_compare import write_paired

    res = write_paired(campaigns["ideal"], campaigns["spread"], tmp_path / "q", window_s=None)
    assert [r["seed"] for r in res["rows"]] == SEEDS[:1]
    assert res["rows"][0]["same_initial_state"] is False and res["stats"]["same_initial_state"] is False


def test_cli_refuses_different_durations(campaigns: dict, tmp_path) -> None:
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "campaign-compare", str(campaigns["ideal"]), str(campaigns["short"]),
           "--out", str(tmp_path / "r")]
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().startswith("error: the campaigns ran different durations") and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
