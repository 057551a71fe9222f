"""Truth checksums and truth references of shipped scenarios.

    python bench/truth_checksums.py [--duration 7200] SCENARIO...                 # sha256 per scenario
    python bench/truth_checksums.py --reference DIR [--duration 600] SCENARIO...   # write DIR/NAME-600s.json
    python bench/truth_checksums.py --record truth --duration 60 SCENARIO...       # the batch mode's truth

Runs each scenario in-process (deterministic, same code path as multi-process). The checksum (sha256
of every `truth` payload in order) is a promise for one machine and one set of packages: compare
checksums made before and after a change on the same machine to show a refactor keeps the truth bit
for bit. Across machines the floating-point kernels differ (docs/determinism.md), so the committed
regression guard is a reference of positions and velocities per step (`--reference`), which
tests/test_truth_checksums.py compares with a tolerance chosen from the measured drift.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def truth_sha256(scenario: str, duration_s: float, out: Path, record: str = "all") -> str:
    """sha256 of every truth payload of the scenario's in-process run; `record="truth"`: the batch
    mode where the scenario allows it (deploy/batch.py), whose truth must be the per-agent run's."""
    from mcap.reader import make_reader

    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(scenario).with_overrides(duration_s=duration_s)
    run_in_process(sc, out, "checksum", record=record)
    h = hashlib.sha256()
    with open(out / "run.mcap", "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic.endswith("truth"):
                h.update(message.data)
    return h.hexdigest()


REFERENCE_ROWS = 61
"""Steps a reference keeps: every one of a 10 min run at 10 s steps; evenly strided for longer runs."""


def truth_arrays(run_dir: Path) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray]:
    """(t_s (K,), spacecraft ids, positions (K, N, 3), velocities (K, N, 3)) of a run's recorded
    spacecraft truth, in step order (dashboards/frames.py reads the recording)."""
    from swarmhil.dashboards.frames import read_frames

    tr = read_frames(run_dir / "run.mcap")["truth"]
    tr = tr[tr["kind"] == "spacecraft"].sort_values(["step", "id"], kind="stable")
    ids = sorted(tr["id"].unique())
    k = tr["step"].nunique()
    pos = tr[["x_m", "y_m", "z_m"]].to_numpy().reshape(k, len(ids), 3)
    vel = tr[["vx_mps", "vy_mps", "vz_mps"]].to_numpy().reshape(k, len(ids), 3)
    return tr.drop_duplicates("step")["t_s"].to_numpy(), ids, pos, vel


def truth_reference(run_dir: Path) -> dict:
    """{"t_s": [...], "ids": [...], "position_m": K x N x 3, "velocity_mps": K x N x 3} of a run's
    spacecraft truth, at most REFERENCE_ROWS steps (the first, every stride-th, the last)."""
    t, ids, pos, vel = truth_arrays(run_dir)
    k = len(t)
    keep = sorted(set(range(0, k, -(-k // REFERENCE_ROWS))) | {k - 1})
    return {"t_s": t[keep].tolist(), "ids": ids, "position_m": pos[keep].tolist(), "velocity_mps": vel[keep].tolist()}


def reference_path(directory: Path, scenario: str, duration_s: float) -> Path:
    return directory / f"{Path(scenario).stem}-{duration_s:g}s.json"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--duration", type=float, default=7200.0)
    ap.add_argument("--reference", type=Path, default=None, help="write truth references into this folder")
    ap.add_argument("--record", choices=["all", "truth"], default="all",
                    help="truth: run in batch mode where the scenario allows (the same truth, bit for bit)")
    a = ap.parse_args()
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for s in a.scenarios:
            run_dir = Path(d) / Path(s).stem
            out[Path(s).stem] = truth_sha256(s, a.duration, run_dir, a.record)
            print(Path(s).stem, out[Path(s).stem], file=sys.stderr, flush=True)
            if a.reference is not None:
                path = reference_path(a.reference, s, a.duration)
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(truth_reference(run_dir)) + "\n")
                print("wrote", path, file=sys.stderr)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
