"""missions/p000_capture/report/sweep.py: the reduction table pairs each seed's event run with the every-step and
1 Hz runs of the same seed and case, from the link counters in summary.json (written here by hand:
the runs themselves take ~10 min each; docs/paper000-reproduction.md has the real ones)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def _run(parent: Path, name: str, state_tx: int, lm_bytes: int = 1000) -> None:
    d = parent / name
    d.mkdir()
    met = {"agents": ["a0", "a1"], "chase_entry_s": {"a0": 1.0}, "in_chase_at_end": 2, "min_surface_m": 0.5,
           "min_pair_m": 3.0, "every_step_ratio": state_tx / 1000, "hz1_ratio": state_tx / 50,
           "link": {"per_type": {"p000-state": {"tx_messages": state_tx, "tx_payload_bytes": 84 * state_tx,
                                                "rx_payload_bytes": 3 * 84 * state_tx},
                                 "p000-landmarks": {"tx_payload_bytes": lm_bytes, "rx_payload_bytes": 3 * lm_bytes}}}}
    (d / "summary.json").write_text(json.dumps({"wall_s": 1.0, "metrics": {"p000-capture": met}}))


def test_reduction_pairs_runs_by_seed_and_case(tmp_path: Path) -> None:
    from swarmhil.missions.p000_capture.report.sweep import load_runs, reduction_table

    for seed, (ev, per, every) in {1: (20, 40, 1000), 2: (30, 50, 1250)}.items():
        _run(tmp_path, f"c10-s{seed}-event", ev)
        _run(tmp_path, f"c10-s{seed}-1hz", per)
        _run(tmp_path, f"c10-s{seed}-every", every)
    _run(tmp_path, "c20-s1-event", 7)
    _run(tmp_path, "c20-s1-event-mp", 7)
    (tmp_path / "not-a-run").mkdir()
    rows = load_runs(tmp_path)
    assert len(rows) == 8 and sum(r["mp"] for r in rows) == 1
    t = reduction_table(rows, 10)
    # by hand: 20/40, 30/50 = 0.5, 0.6: mean 0.55, sample std 0.05 sqrt(2) = 0.0707;
    # 20/1000, 30/1250 = 0.020, 0.024: mean 0.022, std 0.002 sqrt(2) = 0.00283
    assert "| event / 1 Hz (separate runs, same seed) | 0.550 ± 0.071 (0.500–0.600, n = 2) |" in t
    assert "| event / every-step (separate runs, same seed) | 0.022 ± 0.003 (0.020–0.024, n = 2) |" in t
    assert "| 1 Hz run: state packets sent | — |" in reduction_table(rows, 20)  # no baseline run for case (ii)
    p = subprocess.run([sys.executable, "-m", "swarmhil.missions.p000_capture.report.sweep", str(tmp_path / "not-a-run")], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr


def test_spread_by_hand() -> None:
    from swarmhil.missions.p000_capture.report.sweep import spread

    assert spread([]) == "—" and spread([0.5]) == "0.5" and spread([0.5], "{:.3f}") == "0.500"
    assert spread([1.0, 2.0, 6.0]) == "3 ± 2.65 (1–6, n = 3)"  # std sqrt((4 + 1 + 9) / 2) = sqrt(7)
    assert spread([10.0, 10.0]) == "10 ± 0 (10–10, n = 2)"


def test_settle_time_is_the_last_crossing() -> None:
    import numpy as np

    from swarmhil.missions.p000_capture.report import settle_time

    t = np.arange(6.0)
    err = np.array([[5, 0.1, 5], [2, 0.1, 5], [0.5, 0.1, 5], [3, 0.1, 5], [0.2, 0.1, 5], [0.1, np.nan, 0.5]])
    assert settle_time(t, err, 1.0) == [4.0, None, 5.0]
