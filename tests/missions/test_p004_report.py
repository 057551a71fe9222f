"""Paper 004's report section (missions/p004_lbdnn/report/, "p004-servicing"): a brief in-process
run of deploy/scenarios/servicing-6.toml, `swarmhil report RUN`, and the section's metrics against
an independent recomputation from the MCAP — this test's own reading (tests/conftest.py read_mcap
through test_p004_stack.load_run): the defunct craft's and servicers' truth positions, the agents'
commands on sc/<id>/act (not the truth's accel_cmd_mps2), the truth's Δv, summary.json's channel
totals and λ_min(H) built here from the paper's C_i on the ring.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
for p in (ROOT, ROOT / "tests", ROOT / "tests" / "missions"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from test_p004_stack import SERVICERS, swarmhil_run  # noqa: E402

DURATION_S = 10.0
FIGURES = ("p004_tracking.png", "p004_effort.png", "p004_paths.png")
P002_KEYS = {"connectivity", "closest_visible_steady", "closest_visible_whole_run", "visible_pairs_parallelism_steady"}


@pytest.fixture(scope="module")
def reported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("p004report") / "run"
    run = swarmhil_run(out, "--in-process", "--set", f"run.duration_s={DURATION_S:g}")
    p = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "report", str(out), "--no-vector"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return out, run


def paper_lambda_min_h() -> float:
    """λ_min(L ⊗ I3 + blkdiag(C_i^T C_i)) of the ring s1-…-s6-s1 with §6's C_i, b_i = 1."""
    c = {
        "s1": [[1.5124, -1.8904, 0.6818]],
        "s2": [[-0.2772, 1.7565, 1.1135], [0.8638, 1.2110, -1.6287]],
        "s3": [[1.5055, 1.5784, -1.6598], [-1.8437, -1.3206, 1.5125]],
        "s4": [[0.3722, 0.6866, -0.3528], [-1.2097, -0.8414, -1.4315], [1.1332, -0.3498, -1.8633]],
        "s5": [[1.9554, 0.9926, -0.8782], [1.1571, -1.5870, -0.2084], [1.6343, -0.8255, -0.8488]],
        "s6": [[0.0991, -1.6655, 1.6674]],
    }
    lap = 2.0 * np.eye(6) - np.roll(np.eye(6), 1, axis=1) - np.roll(np.eye(6), -1, axis=1)
    h = np.kron(lap, np.eye(3))
    for i, s in enumerate(SERVICERS):
        m = np.array(c[s])
        h[3 * i:3 * i + 3, 3 * i:3 * i + 3] += m.T @ m
    return float(np.linalg.eigvalsh(h)[0])


def test_section_metrics_equal_a_recomputation_from_the_mcap(reported: tuple[Path, dict]) -> None:
    out, run = reported
    summary = json.loads((out / "summary.json").read_text())
    met = summary["metrics"]["p004-servicing"]
    assert run["ids"] == list(SERVICERS) and met["servicers"] == list(SERVICERS)
    assert met["defunct_id"] == "defunct"
    t = run["t"]
    assert len(t) == int(round(DURATION_S / 0.1)) + 1 and met["duration_s"] == pytest.approx(DURATION_S)
    e = np.linalg.norm(run["pos"] - run["defunct_pos"][:, None, :], axis=2)           # (K, 6)
    u = np.stack([np.linalg.norm(run["cmd"][s], axis=1) for s in SERVICERS], axis=1)  # (K-1, 6)
    assert u.shape == (len(t) - 1, 6)
    dv = run["delta_v"][-1]
    approx = dict(rel=1e-9, abs=1e-9)
    assert met["e_start_min_m"] == pytest.approx(e[0].min(), **approx)
    assert met["e_end_max_m"] == pytest.approx(e[-1].max(), **approx)
    assert met["e_end_mean_m"] == pytest.approx(e[-1].mean(), **approx)
    assert met["u_peak_mps2"] == pytest.approx(u.max(), **approx)
    assert met["delta_v_max_mps"] == pytest.approx(dv.max(), **approx)
    assert met["delta_v_total_mps"] == pytest.approx(dv.sum(), **approx)
    assert met["delta_v_total_mps"] == pytest.approx(summary["delta_v_total_mps"], rel=1e-9)
    # 10 s: from kilometres, not yet at the 200 s window nor below 10 m
    assert e[0].min() > 2000.0 and e[-1].max() < e[0].min()
    for k in ("e_mean_after_200s_m", "e_max_after_200s_m", "u_mean_after_200s_mps2", "t_all_below_10m_s"):
        assert met[k] is None, k
    for j, s in enumerate(SERVICERS):
        p = met["per_servicer"][s]
        assert p["e_start_m"] == pytest.approx(e[0, j], **approx)
        assert p["e_end_m"] == pytest.approx(e[-1, j], **approx)
        assert p["u_peak_mps2"] == pytest.approx(u[:, j].max(), **approx)
        assert p["delta_v_mps"] == pytest.approx(dv[j], **approx)
        assert p["t_e_below_10m_s"] is None
    # the link: one 454 B packet per servicer per step (test_p004_stack.PACKET_BYTES)
    tot = summary["channel"]["totals"]
    link = met["link"]
    assert link["tx_payload_bytes"] == tot["tx_payload_bytes"] == 100 * 6 * 454
    assert link["tx_messages"] == tot["tx_messages"] and link["rx_messages"] == tot["rx_messages"]
    assert link["bytes_per_message"] == 454.0
    assert link["tx_bytes_per_s_per_servicer"] == pytest.approx(454 / 0.1)
    # the configured graph and C_i
    assert met["lambda_min_h"] == pytest.approx(paper_lambda_min_h(), rel=1e-12)
    assert met["lambda_min_h"] > 0.0 and met["b"] == {s: 1 for s in SERVICERS}
    assert met["c_rows"] == {"s1": 1, "s2": 2, "s3": 2, "s4": 3, "s5": 3, "s6": 1}


def test_section_figures_exist_and_are_on_the_page(reported: tuple[Path, dict]) -> None:
    out, _run = reported
    page = (out / "report" / "index.html").read_text()
    assert "Paper 004" in page
    for f in FIGURES:
        png = out / "report" / f
        assert png.is_file() and png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG", f
        assert f'src="{f}"' in page, f
    # a mission's page: its own section, not paper 002's figures
    assert 'src="components.png"' not in page


def test_steady_window_metrics(reported: tuple[Path, dict], monkeypatch: pytest.MonkeyPatch) -> None:
    """The after-200 s figures, on this short run with the window moved to 5 s."""
    import swarmhil.missions.p004_lbdnn.report.analysis as sec
    from swarmhil.dashboards.run_config import run_config
    from swarmhil.dashboards.sections import SectionContext, sections_for
    from swarmhil.dashboards.truth_io import read_truth

    out, run = reported
    cfg = run_config(out)
    assert "p004-servicing" in [n for n, _f in sections_for(cfg)]
    assert "p004-servicing" not in [n for n, _f in sections_for({"controller": {"name": "sabatini"}})]
    monkeypatch.setattr(sec, "STEADY_FROM_S", 5.0)
    summary = json.loads((out / "summary.json").read_text())
    ctx = SectionContext(out, out / "run.mcap", out / "report", summary, cfg, read_truth(out / "run.mcap"))
    met, _arrays = sec.compute(ctx)
    t = run["t"]
    e = np.linalg.norm(run["pos"] - run["defunct_pos"][:, None, :], axis=2)
    u = np.stack([np.linalg.norm(run["cmd"][s], axis=1) for s in SERVICERS], axis=1)
    w, wu = t >= 5.0, t[:-1] >= 5.0
    assert met["e_mean_after_200s_m"] == pytest.approx(e[w].mean(), rel=1e-9)
    assert met["e_max_after_200s_m"] == pytest.approx(e[w].max(), rel=1e-9)
    assert met["u_mean_after_200s_mps2"] == pytest.approx(u[wu].mean(), rel=1e-9)
    for j, s in enumerate(SERVICERS):
        assert met["per_servicer"][s]["u_mean_after_200s_mps2"] == pytest.approx(u[wu, j].mean(), rel=1e-9)
    # the 10 m level, moved to where the run gets: the first time from which all stay below
    monkeypatch.setattr(sec, "TRACK_LEVEL_M", 1000.0)
    met, _arrays = sec.compute(ctx)
    above = np.nonzero((e >= 1000.0).any(axis=1))[0]
    assert met["t_all_below_10m_s"] == pytest.approx(t[above[-1] + 1])


def test_overview_is_mission_neutral(reported: tuple[Path, dict]) -> None:
    """Issue 25: servicing-6's report starts with what every mission has and shows none of paper
    002's metrics (they were the overview of every report before)."""
    out, _run = reported
    page = (out / "report" / "index.html").read_text()
    overview = page.split("<h2", 1)[0]
    for word in ("along-track to closest visible", "orbit-minimum a(|dl|-2|de|)", "radial a|de|", "parallelism",
                 "always weakly connected"):
        assert word not in page, word
    for word in ("total dV [m/s]", "dV per spacecraft [m/s]", "closest approach, all pairs", "link traffic", "events"):
        assert word in overview, word
    assert "messages sent" in overview  # servicing-6 flies a link
    assert "p002-swarm" not in page and "Paper 004: servicers converging on the defunct craft" in page
    # nor its numbers: paper 002's metrics hook does not run for servicing-6 (dashboards/metrics.py)
    met = json.loads((out / "summary.json").read_text())["metrics"]
    assert not P002_KEYS & set(met) and set(met["closest_approach"]) == {"all_pairs", "all_pairs_steady", "interpolation"}
    assert met["control"]["delta_v_total_mps"] > 0 and met["closest_approach"]["all_pairs"]["distance_m"] > 0
    series = np.load(out / "metrics_series.npz")
    assert sorted(series.files) == ["delta_v_total_mps", "t_s"]
