"""How far a scenario's truth drifts when the floating-point kernels change (issue 24, docs/determinism.md).

    python bench/kernel_drift.py SCENARIO [SCENARIO ...] [--duration S] [--checkpoints 600,3600,86400]
                                 [--set KEY=VALUE ...] [--json OUT.json]
    python bench/kernel_drift.py --table RESULT.json [RESULT.json ...]   # the table of docs/determinism.md

numpy picks SIMD kernels per CPU and OpenBLAS picks its kernels per CPU, so the last bits of sin,
exp, dot and matrix products differ between machines: a lockstep run is bit-identical on one
machine, and across machines it is a tolerance. This runs each scenario in-process (truth only;
paper 002's batch mode where the scenario allows it) twice, in child processes: once with this
machine's own kernels and once with another set forced through the environment (ALTERNATE_KERNELS:
OpenBLAS's Sandybridge kernels, numpy without its X86_V3 (AVX2/FMA3) loops). It prints, per
checkpoint, the largest position difference of any spacecraft between the two truths, the first
step at which the truths differ at all, and the largest difference over the whole run.

An AVX-512 machine can run the AVX2 kernels (NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL
AVX512_SPR"), not the reverse; the drift between two kernel sets on one machine is of the kind
two machines show (measured: paper 000's case (i) on AVX-512 and on AVX2 + Sandybridge gave the
same first chase entry, 21.70 s; AVX2 with its own kernels 22.70 s).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

ALTERNATE_KERNELS = {"OPENBLAS_CORETYPE": "Sandybridge", "NPY_DISABLE_CPU_FEATURES": "X86_V3"}
"""The other kernel set this machine can run (an AVX2 machine: OpenBLAS's pre-FMA kernels and numpy's
X86_V2 loops). Checked to change the last bits of sabatini-20's truth here."""


def run_truth(scenario: str, duration_s: float, out: Path, env_extra: dict[str, str],
              overrides: list[str]) -> None:
    """One in-process, truth-only run of `scenario` in a child process with `env_extra` set."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", **env_extra)
    sets = [a for kv in overrides for a in ("--set", kv)]
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", scenario, "--in-process", "--record", "truth", "--no-progress",
           "--duration", str(duration_s), "--out", str(out), "--overwrite", *sets]
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"kernel_drift: {' '.join(cmd)} failed ({p.returncode}): {p.stderr[-2000:]}")


def drift(a: Path, b: Path, checkpoints_s: list[float]) -> dict:
    """Position differences between the truths of runs a and b (same scenario and length)."""
    from truth_checksums import truth_arrays

    ta, ids_a, pa, _ = truth_arrays(a)
    tb, ids_b, pb, _ = truth_arrays(b)
    if ids_a != ids_b or len(ta) != len(tb):
        raise ValueError(f"{a} and {b} do not hold the same spacecraft and steps")
    d = np.linalg.norm(pa - pb, axis=2).max(axis=1)  # (K,) worst spacecraft per step
    differ = np.nonzero(d > 0.0)[0]
    out = {"steps": int(len(ta)), "duration_s": float(ta[-1]), "first_difference_t_s": None if not len(differ)
           else float(ta[differ[0]]), "max_m": float(d.max()), "at_m": {}}
    for c in checkpoints_s:
        if c <= ta[-1] + 1e-9:
            out["at_m"][f"{c:g}"] = float(d[: int(np.searchsorted(ta, c, side="right"))].max())
    return out


def _t(seconds: float) -> str:
    return f"{seconds / 3600:.3g} h" if seconds >= 3600 else (f"{seconds / 60:.3g} min" if seconds >= 600 else f"{seconds:.3g} s")


def markdown_table(results: dict[str, dict]) -> str:
    """The drift table of docs/determinism.md from {scenario: drift(...)}."""
    def m(x: float) -> str:
        return "0" if x == 0.0 else f"{x:.2g}"

    lines = ["| scenario | simulated | first difference | largest position difference by [m] | over the run [m] |",
             "|---|---:|---:|---|---:|"]
    for name, r in results.items():
        first = "never" if r["first_difference_t_s"] is None else _t(r["first_difference_t_s"])
        at = "; ".join(f"{_t(float(t))}: {m(d)}" for t, d in r["at_m"].items()) or "-"
        lines.append(f"| {name} | {_t(r['duration_s'])} | {first} | {at} | {m(r['max_m'])} |")
    return "\n".join(lines)


def main() -> None:
    if sys.argv[1:2] == ["--table"]:
        results: dict[str, dict] = {}
        for path in sys.argv[2:]:
            results.update(json.loads(Path(path).read_text())["results"])
        print(markdown_table(results))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenarios", nargs="+")
    ap.add_argument("--duration", type=float, default=None, help="seconds (default: each scenario's own)")
    ap.add_argument("--checkpoints", default="600,3600,86400", help="comma-separated times [s]")
    ap.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    cps = [float(x) for x in a.checkpoints.split(",") if x]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for s in a.scenarios:
            from swarmhil.deploy.scenario import load_scenario

            dur = a.duration if a.duration is not None else load_scenario(s).duration_s
            name = Path(s).stem
            own, other = Path(tmp) / f"{name}-own", Path(tmp) / f"{name}-alt"
            run_truth(s, dur, own, {}, a.overrides)
            run_truth(s, dur, other, ALTERNATE_KERNELS, a.overrides)
            results[name] = drift(own, other, cps)
            print(name, json.dumps(results[name]), flush=True)
    if a.json is not None:
        a.json.write_text(json.dumps({"alternate_kernels": ALTERNATE_KERNELS, "results": results}, indent=1) + "\n")


if __name__ == "__main__":
    main()
