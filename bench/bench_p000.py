"""Paper 000 benchmark: this tree's flight software against an older commit's, side by side in one
invocation, as ratios old / new (issue 29). Not a test: figures go to docs/paper000-reproduction.md.

Each side runs in its own subprocess on its own source tree (the older commit is exported with
`git archive` into a temporary directory; both use this venv), one job after the other:

- `fits`: CPU time of the GNC-TLS ellipsoid fits on the same synthetic ellipsoids with outliers
  (the cold `gnc_tls_fit`; the in-loop update: `warm_fit`, or `track_fit` in older trees), median
  over fits, and the fraction of cold fits within 2 % of the truth;
- `room`: the room's closed loop (tests/missions/test_p000_closed_loop.run_capture, case (i), seed 1,
  dt 0.05 s: the CI system test `test_system_case_i_550s_paper_step` at `--room-duration 550`);
- `run`: an in-process run of a scenario on the stack (`deploy.launcher.run_in_process`: plant,
  sensing kind, agents, recorder), by default 60 s of case (ii), capture-20.

Wall and CPU time of each; the ratio is CPU old / CPU new (wall beside it: on a shared machine it
carries the load, printed at the start and the end).

    nice -n 10 .venv/bin/python bench/bench_p000.py                      # against a8239fd (before issue 29)
    nice -n 10 .venv/bin/python bench/bench_p000.py --jobs fits --fits 20
    nice -n 10 .venv/bin/python bench/bench_p000.py --room-duration 550 --jobs room
    nice -n 10 .venv/bin/python bench/bench_p000.py --mp --duration 60   # multi-process vs in-process (this tree)
    nice -n 10 .venv/bin/python bench/bench_p000.py --profile --duration 60  # where the CPU goes (this tree)
    nice -n 10 .venv/bin/python bench/bench_p000.py --parts --duration 60    # the same parts without a profiler
    nice -n 10 .venv/bin/python bench/bench_p000.py --against main --jobs run --record truth --record-against all
        # this tree's batch mode (`--record truth`) against main's `swarmhil run --in-process` (every message)
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
BEFORE = "a8239fd"  # main before issue 29's speed-up of paper 000's flight software
CAPTURE_20 = "deploy/scenarios/capture-20.toml"


def synthetic(seed: int, axes: np.ndarray, outliers: float, n: int = 200) -> tuple[np.ndarray, object]:
    """n noisy surface points (σ 2 cm) of a randomly posed ellipsoid, a fraction replaced by points
    uniform in a 12 m box about its centre; and the true ellipsoid."""
    from scipy.spatial.transform import Rotation

    from swarmhil.missions.p000_capture.contract import Ellipsoid, surface_landmarks

    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=seed).as_matrix()
    c = rng.uniform(-3, 3, 3)
    pts, _ = surface_landmarks(axes, n)
    pts = pts @ rot.T + c + rng.normal(0, 0.02, (n, 3))
    idx = rng.permutation(n)[: int(outliers * n)]
    pts[idx] = c + rng.uniform(-6, 6, (len(idx), 3))
    return pts, Ellipsoid(c, rot, axes)


def job_fits(fits: int, outliers: float) -> dict[str, float]:
    """Median CPU time [s] of a cold GNC-TLS fit and of the in-loop update from last period's
    estimate (the truth moved by 5 cm and scaled by 2 %), half case (i), half case (ii) shapes."""
    from swarmhil.missions.p000_capture.fsw import gnc_tls as g
    from swarmhil.missions.p000_capture.contract import Ellipsoid

    update = getattr(g, "warm_fit", None) or getattr(g, "track_fit")
    cold, warm, ok = [], [], 0
    for s in range(fits):
        axes = np.array([2.6, 1.9, 1.4]) if s % 2 == 0 else np.array([4.0, 1.3, 1.0])
        pts, truth = synthetic(s, axes, outliers)
        t0 = time.process_time()
        fit = g.gnc_tls_fit(pts)
        cold.append(time.process_time() - t0)
        ok += bool(np.allclose(np.sort(fit.ellipsoid.semi_axes_m), np.sort(axes), rtol=0.02))
        prev = Ellipsoid(truth.centre_m + 0.05, truth.rotation, truth.semi_axes_m * 1.02)
        t0 = time.process_time()
        for _ in range(5):
            update(pts, prev)
        warm.append((time.process_time() - t0) / 5)
    return {"cold_fit_median_s": statistics.median(cold), "cold_fit_max_s": max(cold),
            "update_median_s": statistics.median(warm), "cold_within_2pct": ok / fits}


def _timed(fn) -> tuple[dict[str, float], object]:
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return {"wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0}, out


def job_room(duration: float) -> dict[str, float]:
    sys.path.insert(0, str(Path.cwd() / "tests" / "missions"))
    import test_p000_closed_loop as cl

    t, res = _timed(lambda: cl.run_capture(duration_s=duration, dt_s=0.05, seed=1))
    return {**t, "state_broadcasts": res.state_broadcasts, "min_surface_m": res.min_surface_m,
            "axes_err_max": max(res.axes_err, default=float("nan"))}


def job_run(scenario: str, duration: float, record: str = "all") -> dict[str, object]:
    sc, (t, res) = _in_process(scenario, duration, _timed, record)
    return {**t, "steps": sc.steps, "agents": len(sc.ids), "batch": getattr(res, "summary", {}).get("batch")}


# The rows of the two tables of docs/paper000-reproduction.md: (label, where `--profile` finds it:
# (file part, function name) or None, what `--parts` wraps: (module, "Class.method ...") or None).
# Each row is the CPU time of that function with its callees, so rows nest.
ROWS = [
    ("whole run (`run_in_process`)", ("deploy/launcher", "run_in_process"), None),
    ("plant steps (`publish_step`: everything a step runs, the in-memory bus's callbacks included)", None,
     ("swarmhil.plant.node", "PlantNode.publish_step")),
    ("the 20 agents' stimulus handling (decode, flight software, command, telemetry)", ("agent/node", "_on_stimulus"),
     ("swarmhil.agent.node", "AgentNode._on_stimulus")),
    ("batch mode (`--record truth`): the flight software of all agents (`BatchHook.commands`, stimuli included)",
     ("deploy/batch", "commands"), ("swarmhil.deploy.batch", "BatchHook.commands")),
    ("of which the flight software's `step`", ("p000_capture/fsw/controller", "step"),
     ("swarmhil.missions.p000_capture.fsw.controller", "CaptureController.step")),
    ("of which the landmark fits (`_fit`: pool, cold GNC-TLS and warm fits)", ("p000_capture/fsw/controller", "_fit"),
     ("swarmhil.missions.p000_capture.fsw.controller", "CaptureController._fit")),
    ("of which cold `gnc_tls_fit`", ("p000_capture/fsw/gnc_tls", "gnc_tls_fit"), None),
    ("of which `warm_fit`", ("p000_capture/fsw/gnc_tls", "warm_fit"), None),
    ("closest surface point (`surface_frame`: agents' estimate and the sensor's truth)",
     ("p000_capture/contract", "surface_frame"), None),
    ("consensus (eq. 30)", ("p000_capture/fsw/estimate", "consensus"), None),
    ("APF (eq. 23)", ("p000_capture/fsw/apf", "apf_force"), None),
    ("sensing kind `p000-landmarks` (`stimulus`, 20 a step)", ("p000_capture/sense", "stimulus"),
     ("swarmhil.missions.p000_capture.sense", "P000LandmarkKind.stimulus")),
    ("of which `landmark_returns` (visibility, noise, outliers)", ("p000_capture/sense", "landmark_returns"), None),
    ("recorder (every message; Foxglove scene of every truth)", ("bus/recorder", "_on_sample"),
     ("swarmhil.bus.recorder", "RecorderNode._on_sample")),
    ("decode + validation of every received message", ("bus/codec", "decode"), None),
    ("of which the non-finite walk", ("bus/codec", "_non_finite_field"), None),
    ("link channel: commands and windows (`_on_act`)", ("link/node", "_on_act"), ("swarmhil.link.node", "ChannelNode._on_act")),
    ("link channel: truth (`_on_truth`)", ("link/node", "_on_truth"), ("swarmhil.link.node", "ChannelNode._on_truth")),
    ("plant: command decode and collection (`_on_command`)", ("plant/node", "_on_command"),
     ("swarmhil.plant.node", "PlantNode._on_command")),
    ("plant: dynamics (CW, attitude RK4, limits: `MissionWorld.step`)", ("plant/mission_world", "step"),
     ("swarmhil.plant.mission_world", "MissionWorld.step")),
]


def _in_process(scenario: str, duration: float, around: Callable[[Callable[[], object]], object],
                record: str = "all") -> tuple[object, object]:
    """The scenario's in-process run of `duration` s, called through `around` (timing, profiling);
    `record="truth"`: the batch mode where the tree has it for the scenario."""
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(scenario).with_overrides(duration_s=duration)
    with tempfile.TemporaryDirectory(prefix="swarmhil-bench-p000-") as out:
        return sc, around(lambda: run_in_process(sc, Path(out), "bench-p000", record=record))


def job_profile(scenario: str, duration: float, record: str = "all") -> dict[str, object]:
    """The in-process run under cProfile counting CPU time; the cumulative seconds of ROWS."""
    import cProfile
    import pstats

    prof = cProfile.Profile(time.process_time)
    sc, _ = _in_process(scenario, duration, prof.runcall, record)
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    rows = {}
    for label, found, _w in ROWS:
        if found is not None:
            cum = [(ct, nc) for (f, _l, name), (_cc, nc, _tt, ct, _c) in stats.items() if found[0] in f and name == found[1]]
            rows[label] = max(cum, default=(0.0, 0))
    return {"steps": sc.steps, "agents": len(sc.ids), "rows": rows}


def job_parts(scenario: str, duration: float, record: str = "all") -> dict[str, object]:
    """The in-process run with ROWS' methods wrapped (one process_time pair per call, ~1 us): CPU s and calls."""
    import importlib

    cpu: dict[str, float] = {}
    calls: dict[str, int] = {}

    def wrap(label: str, owner: type, name: str) -> None:
        f, pt = getattr(owner, name), time.process_time

        def timed(*args: object, **kw: object) -> object:
            t0 = pt()
            try:
                return f(*args, **kw)
            finally:
                cpu[label] = cpu.get(label, 0.0) + pt() - t0
                calls[label] = calls.get(label, 0) + 1
        setattr(owner, name, timed)

    for label, _f, wrapped in ROWS:
        if wrapped is not None:
            for m in wrapped[1].split():
                cls, name = m.split(".")
                wrap(label, getattr(importlib.import_module(wrapped[0]), cls), name)
    sc, (t, _) = _in_process(scenario, duration, _timed, record)
    return {**t, "steps": sc.steps, "agents": len(sc.ids),
            "rows": {label: (cpu.get(label, 0.0), calls.get(label, 0)) for label, _f, w in ROWS if w is not None}}


def worker(a: argparse.Namespace) -> None:
    """One job on the tree in the current directory; one JSON line on stdout."""
    sys.path.insert(0, os.getcwd())
    if a.job == "fits":
        out = job_fits(a.fits, a.outliers)
    elif a.job == "profile":
        out = job_profile(a.scenario, a.duration, a.record)
    elif a.job == "parts":
        out = job_parts(a.scenario, a.duration, a.record)
    elif a.job == "room":
        out = job_room(a.room_duration)
    else:
        out = job_run(a.scenario, a.duration, a.record)
    print(json.dumps(out))


def run_side(tree: Path, job: str, a: argparse.Namespace, record: str | None = None) -> dict[str, float]:
    cmd = [sys.executable, str(ROOT / "bench" / "bench_p000.py"), "--worker", job, "--fits", str(a.fits),
           "--outliers", str(a.outliers), "--room-duration", str(a.room_duration), "--scenario", a.scenario,
           "--duration", str(a.duration), "--record", record or a.record]
    p = subprocess.run(cmd, cwd=tree, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"{job} on {tree} failed: {p.stderr.strip().splitlines()[-1:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def export(rev: str, into: Path) -> Path:
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def bench_mp(scenario: str, duration: float) -> dict[str, float]:
    """This tree: the scenario multi-process over Zenoh and in-process, wall of each."""
    from swarmhil.deploy.launcher import MultiProcessRun, run_in_process
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(scenario).with_overrides(duration_s=duration)
    with tempfile.TemporaryDirectory(prefix="swarmhil-bench-p000-") as d:
        out = Path(d)
        t0 = time.perf_counter()
        res = MultiProcessRun(scenario, sc, out / "mp", "bench-p000-mp", progress=False,
                              overrides={"duration": duration}).execute()
        mp = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_in_process(sc, out / "ip", "bench-p000-ip")
        ip = time.perf_counter() - t0
    return {"steps": sc.steps, "agents": len(sc.ids), "multi_process_wall_s": mp,
            "multi_process_loop_s": res.summary.get("loop_wall_s", float("nan")), "in_process_wall_s": ip,
            "mp_over_ip": mp / ip}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", default=BEFORE, help=f"the older commit (default {BEFORE})")
    ap.add_argument("--jobs", default="fits,room,run", help="comma-separated: fits, room, run")
    ap.add_argument("--fits", type=int, default=12, help="synthetic GNC fits")
    ap.add_argument("--outliers", type=float, default=0.1, help="outlier fraction of the synthetic fits")
    ap.add_argument("--room-duration", type=float, default=60.0, help="simulated seconds of the room loop")
    ap.add_argument("--scenario", default=CAPTURE_20, help="scenario of the in-process run (from the tree's root)")
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds of the in-process run")
    ap.add_argument("--record", choices=["all", "truth"], default="all",
                    help="what the in-process run records (truth: the batch mode where the tree has it)")
    ap.add_argument("--record-against", choices=["all", "truth"], default=None,
                    help="the older tree's --record (default: the same)")
    ap.add_argument("--mp", action="store_true", help="only this tree: multi-process vs in-process")
    ap.add_argument("--profile", action="store_true", help="only this tree: where the in-process run's CPU goes")
    ap.add_argument("--parts", action="store_true", help="only this tree: CPU of each part, no profiler")
    ap.add_argument("--worker", choices=["fits", "room", "run", "profile", "parts"], help=argparse.SUPPRESS)
    a = ap.parse_args()
    jobs = [j for j in a.jobs.split(",") if j]
    if (a.duration <= 0 or a.room_duration <= 0 or a.fits < 1 or not 0 <= a.outliers < 1
            or not set(jobs) <= {"fits", "room", "run"}):
        ap.error("--duration, --room-duration > 0, --fits >= 1, 0 <= --outliers < 1, --jobs of fits,room,run")
    if a.worker:
        worker(argparse.Namespace(**{**vars(a), "job": a.worker}))
        return
    res: dict[str, object] = {"loadavg_start": os.getloadavg(), "against": a.against}
    if a.profile or a.parts:
        job = "profile" if a.profile else "parts"
        r = res[job] = run_side(ROOT, job, a)
        how = "cumulative CPU s under cProfile(time.process_time)" if a.profile else \
            f"CPU s per part, no profiler; the whole run {r['cpu_s']:.1f} s CPU, {r['wall_s']:.0f} s wall"
        print(f"{Path(a.scenario).name} in-process, {a.duration:g} s ({r['steps']} steps, {r['agents']} agents): {how}")
        print("| where | calls | CPU s |\n|---|---:|---:|")
        for label, (cum, calls) in r["rows"].items():
            print(f"| {label} | {calls} | {cum:.1f} |")
    elif a.mp:
        sys.path.insert(0, str(ROOT))
        r = bench_mp(str(ROOT / a.scenario), a.duration)
        res["mp"] = r
        print(f"{Path(a.scenario).name}: {r['agents']} agents, {r['steps']} steps: multi-process "
              f"{r['multi_process_wall_s']:.0f} s (plant loop {r['multi_process_loop_s']:.0f} s), in-process "
              f"{r['in_process_wall_s']:.0f} s, ratio {r['mp_over_ip']:.2f}")
    else:
        with tempfile.TemporaryDirectory(prefix="swarmhil-bench-p000-old-") as d:
            old_tree = export(a.against, Path(d))
            for job in jobs:
                old, new = run_side(old_tree, job, a, a.record_against), run_side(ROOT, job, a)
                res[job] = {"old": old, "new": new}
                if job == "fits":
                    print(f"GNC-TLS, 200 points, {a.outliers:.0%} outliers, {a.fits} fits (CPU, median): cold "
                          f"{old['cold_fit_median_s'] * 1e3:.0f} -> {new['cold_fit_median_s'] * 1e3:.0f} ms "
                          f"(x{old['cold_fit_median_s'] / new['cold_fit_median_s']:.1f}; within 2 %: "
                          f"{old['cold_within_2pct']:.0%} -> {new['cold_within_2pct']:.0%}), in-loop update "
                          f"{old['update_median_s'] * 1e3:.1f} -> {new['update_median_s'] * 1e3:.2f} ms "
                          f"(x{old['update_median_s'] / new['update_median_s']:.1f})")
                else:
                    what = (f"room loop, case (i), {a.room_duration:g} s" if job == "room"
                            else f"{Path(a.scenario).name} in-process, {a.duration:g} s (record "
                                 f"{a.record_against or a.record} -> {a.record}, batch mode {old.get('batch')} -> "
                                 f"{new.get('batch')})")
                    print(f"{what}: CPU {old['cpu_s']:.1f} -> {new['cpu_s']:.1f} s "
                          f"(x{old['cpu_s'] / new['cpu_s']:.2f}), wall {old['wall_s']:.1f} -> {new['wall_s']:.1f} s "
                          f"(x{old['wall_s'] / new['wall_s']:.2f})")
    res["loadavg_end"] = os.getloadavg()
    print(json.dumps(res))


if __name__ == "__main__":
    main()
