"""The camera scenarios (issue 36) in-process with `--record truth`: the per-agent path against the
batch path, CPU seconds side by side in one invocation, and a 20-seed campaign estimate. Not a test:
figures go to docs/performance.md.

Both paths run what `swarmhil run SCENARIO --in-process --record truth` runs
(deploy.launcher.run_in_process(record="truth")): the per-agent one with the batch mode off
(`opts={"batch": False}`: one agent node per spacecraft, the scene stimuli as messages on the
in-memory bus), the batch one through deploy/batch.py `BatchHook` (the plant's SceneBatch arrays,
each spacecraft's own Perception in agent/batch.py BatchPerception). The truth of the two is
compared (sha256 of every truth payload, the check of tests/test_batch_camera.py). A short run of
each first loads every module and the numba kernels, so neither import nor JIT time is in the
figures. CPU is this process's (`time.process_time`); the load average is printed at the start and
the end (the machine is shared).

    nice -n 10 .venv/bin/python bench/bench_camera_batch.py                  # both scenarios, 24 h
    nice -n 10 .venv/bin/python bench/bench_camera_batch.py --hours 6 --no-per-agent
    .venv/bin/python bench/bench_camera_batch.py --parallel     # one scenario per core, at the same time

With `--parallel` each scenario runs in its own child process (this script with `--scenarios NAME`),
at the same time, as a campaign on 2 cores would run them; each child's figures are its own CPU.

With `--ref REV` the batch path of the code at git revision REV (exported to a temporary directory)
runs beside this tree's, each scenario as two child processes at the same time (one per core, so
both see the same load), and the ratio old / new of their CPU is printed with both truths (the
batch mode's rule: the same bytes):

    nice -n 10 .venv/bin/python bench/bench_camera_batch.py --ref main --scenarios sabatini-20-camera-filter
"""
from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SCENARIOS = ["sabatini-20-camera-exact", "sabatini-20-camera-filter"]


def truth_sha(path: Path) -> str:
    from mcap.reader import make_reader

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages(log_time_order=False):
            if ch.topic == "truth":
                h.update(m.data)
    return h.hexdigest()


def one(sc, batch: bool, tmp: Path, tag: str) -> tuple[float, float, str, dict]:
    from swarmhil.deploy.launcher import run_in_process

    out = tmp / tag
    c0, w0 = time.process_time(), time.monotonic()
    res = run_in_process(sc, out, "bench", record="truth", opts=None if batch else {"batch": False})
    cpu, wall = time.process_time() - c0, time.monotonic() - w0
    assert bool((res.summary.get("batch") or {}).get("used")) == batch, res.summary.get("batch")
    return cpu, wall, truth_sha(out / "run.mcap"), res.summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--seed", type=int, help="the scenario's [run].seed (default: the scenario's own)")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--no-per-agent", action="store_true", help="the batch path only")
    ap.add_argument("--seeds", type=int, default=20, help="campaign size of the estimate")
    ap.add_argument("--cores", type=int, default=2, help="cores of the estimate")
    ap.add_argument("--parallel", action="store_true", help="each scenario in its own child process, all at once")
    ap.add_argument("--ref", help="git revision whose batch path runs beside this tree's (old / new, one per core)")
    ap.add_argument("--tree", help=argparse.SUPPRESS)  # (a child of --ref: import swarmhil from this directory)
    a = ap.parse_args()
    if a.ref:
        compare_ref(a)
        return
    root = ROOT
    if a.tree:
        root = Path(a.tree)
        sys.path.insert(0, str(root))
    if a.parallel:
        import re
        import subprocess

        print(f"load average at start: {os.getloadavg()}, cores: {os.cpu_count()}", flush=True)
        args = [f"--hours={a.hours}", f"--seeds={a.seeds}", f"--cores={a.cores}"] + (["--no-per-agent"] if a.no_per_agent else [])
        kids = [subprocess.Popen([sys.executable, __file__, f"--scenarios={n}", *args], stdout=subprocess.PIPE, text=True)
                for n in a.scenarios.split(",")]
        total = 0.0
        for k in kids:
            out, _ = k.communicate()
            for line in out.splitlines():
                if line.startswith(tuple(SCENARIOS)):
                    print(line, flush=True)
                    total += float(re.search(r"batch ([0-9.]+) s CPU", line).group(1))
        print(f"load average at end: {os.getloadavg()}")
        total *= a.seeds * 24.0 / a.hours
        print(f"campaign estimate: {a.seeds} seeds x 24 h of each scenario on {a.cores} cores: "
              f"{total:.0f} s CPU, {total / a.cores / 60:.1f} min with {a.cores} runs at a time (per-run CPU as measured here)")
        return
    from swarmhil.deploy.scenario import load_scenario

    print(f"load average at start: {os.getloadavg()}, cores: {os.cpu_count()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for name in a.scenarios.split(","):
            base = load_scenario(root / "deploy" / "scenarios" / f"{name}.toml")
            one(base.with_overrides(duration_s=60.0), True, tmp, f"{name}-warm")  # imports, numba kernels
            sc = base.with_overrides(duration_s=a.hours * 3600.0, seed=a.seed)
            cpu_b, wall_b, sha_b, sum_b = one(sc, True, tmp, f"{name}-batch")
            line = (f"{name} {a.hours:g} h: batch {cpu_b:.1f} s CPU ({wall_b:.1f} s wall), dV {sum_b['delta_v_total_mps']:.6g} m/s, "
                    f"faults {sum_b.get('agent_faults')}, truth {sha_b[:16]}")
            row = {"name": name, "batch": cpu_b}
            if not a.no_per_agent:
                cpu_p, wall_p, sha_p, sum_p = one(sc, False, tmp, f"{name}-agents")
                line += (f"; per-agent {cpu_p:.1f} s CPU ({wall_p:.1f} s wall), truth {sha_p[:16]}: "
                         f"{'SAME' if sha_p == sha_b else 'DIFFERENT'}, x{cpu_p / cpu_b:.2f}")
                row["per_agent"] = cpu_p
            print(line, flush=True)
            rows.append(row)
    print(f"load average at end: {os.getloadavg()}")
    total = sum(r["batch"] for r in rows) * a.seeds * 24.0 / a.hours
    print(f"campaign estimate: {a.seeds} seeds x 24 h of each of {len(rows)} scenarios on {a.cores} cores: "
          f"{total:.0f} s CPU, {total / a.cores / 60:.1f} min with {a.cores} runs at a time (per-run CPU as measured here)")


def compare_ref(a: argparse.Namespace) -> None:
    """--ref: per scenario, REV's batch run and this tree's at the same time (two children, one per core)."""
    import re
    import subprocess

    with tempfile.TemporaryDirectory() as d:
        ref = Path(d) / "ref"
        ref.mkdir()
        rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", a.ref], check=True, capture_output=True, text=True).stdout.strip()
        here = subprocess.run(["git", "-C", str(ROOT), "describe", "--always", "--dirty"], check=True, capture_output=True, text=True).stdout.strip()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(ref)], input=archive, check=True)
        print(f"load average at start: {os.getloadavg()}, cores: {os.cpu_count()}; old = {rev}, new = {here}", flush=True)
        common = [f"--hours={a.hours}", "--no-per-agent"] + ([] if a.seed is None else [f"--seed={a.seed}"])
        for name in a.scenarios.split(","):
            kids = {tag: subprocess.Popen([sys.executable, __file__, f"--scenarios={name}", *common, *extra],
                                          stdout=subprocess.PIPE, text=True)
                    for tag, extra in (("old", [f"--tree={ref}"]), ("new", []))}
            got = {}
            for tag, k in kids.items():
                out, _ = k.communicate()
                line = next(ln for ln in out.splitlines() if ln.startswith(name))
                got[tag] = (float(re.search(r"batch ([0-9.]+) s CPU", line).group(1)), re.search(r"truth ([0-9a-f]+)", line).group(1), line)
                print(f"  {tag}: {line}", flush=True)
            (c_old, t_old, _), (c_new, t_new, _) = got["old"], got["new"]
            print(f"{name} {a.hours:g} h batch{'' if a.seed is None else f', seed {a.seed}'}: old {c_old:.1f} s CPU, new {c_new:.1f} s CPU, old / new x{c_old / c_new:.2f}, "
                  f"truth {'SAME' if t_old == t_new else 'DIFFERENT'}", flush=True)
        print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
