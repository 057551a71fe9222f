"""Truth checksums of shipped scenarios (issue 11: the refactor must keep truth bit-identical).

    python bench/truth_checksums.py [--duration 7200] SCENARIO...

Runs each scenario in-process (deterministic, same code path as multi-process) and prints the
sha256 of every `truth` payload in order, as JSON {scenario: sha256}. tests/test_truth_checksums.py
compares against the values recorded before the refactor.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def truth_sha256(scenario: str, duration_s: float, out: Path) -> str:
    from mcap.reader import make_reader

    from deploy.launcher import run_in_process
    from deploy.scenario import load_scenario

    sc = load_scenario(scenario).with_overrides(duration_s=duration_s)
    run_in_process(sc, out, "checksum")
    h = hashlib.sha256()
    with open(out / "run.mcap", "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.topic.endswith("truth"):
                h.update(message.data)
    return h.hexdigest()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--duration", type=float, default=7200.0)
    a = ap.parse_args()
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for s in a.scenarios:
            out[Path(s).stem] = truth_sha256(s, a.duration, Path(d) / Path(s).stem)
            print(Path(s).stem, out[Path(s).stem], file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
