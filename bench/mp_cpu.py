"""Where the CPU of a multi-process lockstep run goes (issue 16): CPU seconds per step of each
process (utime + stime from /proc/PID/stat), over the plant's loop only.

    python bench/mp_cpu.py deploy/scenarios/drift-20.toml --duration 3600 [--out DIR] [--insecure] [--every STEPS]

Runs the scenario with the launcher (deploy/launcher.py), reads the PIDs from DIR/run.json, and
samples every process's CPU time when the plant's clock passes step 1 and again at the last step
(the launcher's progress hook), so start-up and shutdown are left out. Prints one row per process
kind (plant, agent: mean / max over the agents, recorder, router, link channel, launcher) with
CPU ms per step and the share of the total, the loop wall per step, and the load average. The
last line is the result as JSON. `run_with_cpu` is the measurement alone (bench/bench_backbone.py
prints it for each multi-process run of `make bench`).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TICK_S = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float | None:
    """utime + stime of a process (all its threads), seconds; None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / TICK_S  # fields 14 and 15 of proc(5), after "pid (comm)"


def snapshot(pids: dict[str, int]) -> dict[str, float]:
    out = {n: cpu_s(p) for n, p in pids.items()}
    out["launcher"] = time.process_time()
    return {n: v for n, v in out.items() if v is not None}


def kind(name: str) -> str:
    return "agent" if name.startswith("agent-") else name


def kinds(per: dict[str, float]) -> dict[str, list[float]]:
    """CPU per step of each process, grouped by process kind (`kind`)."""
    rows: dict[str, list[float]] = {}
    for n, v in per.items():
        rows.setdefault(kind(n), []).append(v)
    return rows


def run_with_cpu(scenario: str, sc, out: Path, run: str, duration: float, opts: dict | None = None,
                 every: int = 0) -> dict:
    """Run `sc` (the launcher, multi-process) and measure every process's CPU over the plant's loop.

    Returns {"steps", "wall_ms_per_step" (loop wall from step 1 to the last step), "cpu_ms_per_step"
    (per process name), "windows" (with `every`: (step, monotonic s, CPU snapshot) every so many
    steps), "loop_wall_s", "summary"}; raises RuntimeError when the run fails. Hooks the launcher's
    progress update (its dispatcher thread sees every clock step) for the run's duration only."""
    import swarmhil.deploy.launcher as L

    marks: dict[str, tuple[int, float, dict[str, float]]] = {}
    windows: list[tuple[int, float, dict[str, float]]] = []
    lock = threading.Lock()

    def pids() -> dict[str, int]:
        try:
            return {n: int(p) for n, p in json.loads((out / "run.json").read_text())["pids"].items()}
        except (OSError, ValueError, KeyError):
            return {}

    update = L._Progress.update

    def hooked(self, step: int, _wall: float | None = None) -> None:  # the launcher's dispatcher thread
        with lock:
            if step >= 1 and "start" not in marks:
                marks["start"] = (step, time.monotonic(), snapshot(pids()))
            elif step >= sc.steps - 1 and "end" not in marks:
                marks["end"] = (step, time.monotonic(), snapshot(pids()))
            if every and step >= 1 and (not windows or step >= windows[-1][0] + every):
                windows.append((step, time.monotonic(), snapshot(pids())))
        update(self, step, _wall)

    L._Progress.update = hooked  # type: ignore[method-assign]
    try:
        res = L.MultiProcessRun(scenario, sc, out, run, progress=False, overrides={"duration": duration},
                                opts=opts).execute()
    finally:
        L._Progress.update = update  # type: ignore[method-assign]
    if res.exit_code:
        raise RuntimeError(f"the run failed: {res.reason}")
    (k0, t0, c0), (k1, t1, c1) = marks["start"], marks["end"]
    steps = k1 - k0
    return {"steps": steps, "wall_ms_per_step": (t1 - t0) / steps * 1e3,
            "cpu_ms_per_step": {n: (c1[n] - c0[n]) / steps * 1e3 for n in c1 if n in c0},
            "windows": windows, "loop_wall_s": res.summary.get("loop_wall_s"), "summary": res.summary}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario")
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--out")
    ap.add_argument("--insecure", action="store_true", help="no authentication / ACL on the router")
    ap.add_argument("--every", type=int, default=0, help="also a row per window of this many steps (where CPU grows)")
    a = ap.parse_args()
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(a.scenario).with_overrides(duration_s=a.duration)
    out = Path(a.out or tempfile.mkdtemp(prefix="swarmhil-mpcpu-"))
    load0 = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    try:
        m = run_with_cpu(a.scenario, sc, out, f"mpcpu-{sc.name}", a.duration, opts={"secure": not a.insecure},
                         every=a.every)
    except RuntimeError as exc:
        sys.exit(f"error: {exc}")
    per = {n: v / 1e3 for n, v in m["cpu_ms_per_step"].items()}
    rows = kinds(per)
    total = sum(per.values())
    wall = m["wall_ms_per_step"] / 1e3
    steps, windows = m["steps"], m["windows"]
    print(f"{sc.name}: {len(sc.ids)} agents, {steps} steps, loop wall {wall * 1e3:.2f} ms/step, "
          f"load {load0} -> {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print(f"{'process kind':14s} {'n':>3s} {'CPU ms/step (sum)':>18s} {'per process':>12s} {'max':>8s} {'share':>7s}")
    for k, vs in sorted(rows.items(), key=lambda kv: -sum(kv[1])):
        print(f"{k:14s} {len(vs):3d} {sum(vs) * 1e3:18.3f} {sum(vs) / len(vs) * 1e3:12.3f} {max(vs) * 1e3:8.3f} "
              f"{sum(vs) / total:7.1%}")
    print(f"{'total':14s} {len(per):3d} {total * 1e3:18.3f}   (2 cores: {total / wall / 2:.0%} of the wall)")
    if len(windows) > 1:
        print(f"{'window (steps)':16s} {'wall ms/step':>12s} " + " ".join(f"{k:>9s}" for k in sorted(rows)) + "   (CPU ms/step, sum per kind)")
        for (ka, ta, ca), (kb, tb, cb) in zip(windows, windows[1:]):
            per_kind: dict[str, float] = {}
            for n in cb:
                if n in ca:
                    per_kind[kind(n)] = per_kind.get(kind(n), 0.0) + (cb[n] - ca[n]) / (kb - ka)
            print(f"{ka:6d}..{kb:<8d} {(tb - ta) / (kb - ka) * 1e3:12.2f} "
                  + " ".join(f"{per_kind.get(k, 0.0) * 1e3:9.2f}" for k in sorted(rows)))
    print(json.dumps({"scenario": sc.name, "steps": steps, "wall_ms_per_step": wall * 1e3,
                      "cpu_ms_per_step": m["cpu_ms_per_step"], "load_start": load0,
                      "loop_wall_s": m["loop_wall_s"], "out": str(out)}))


if __name__ == "__main__":
    main()
