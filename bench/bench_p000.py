"""Paper 000 benchmark (issue 12): wall time of a capture case multi-process (Zenoh, one process per
agent + plant + link channel, lockstep) and in-process, in one invocation, with their ratio; and the
time per GNC-TLS ellipsoid fit (cold `gnc_tls_fit` and the in-loop `track_fit`) on synthetic
ellipsoids with outliers (median over fits). Not a test: figures go to docs/paper000-reproduction.md.

    nice -n 10 .venv/bin/python bench/bench_p000.py                         # 550 s of case (ii), 20 agents
    nice -n 10 .venv/bin/python bench/bench_p000.py --duration 60 --fits 12
    nice -n 10 .venv/bin/python bench/bench_p000.py --no-runs                # GNC fits only
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def synthetic(seed: int, axes: np.ndarray, outliers: float, n: int = 200) -> tuple[np.ndarray, object]:
    """n noisy surface points (σ 2 cm) of a randomly posed ellipsoid, a fraction replaced by points
    uniform in a 12 m box about its centre; and the true ellipsoid."""
    from scipy.spatial.transform import Rotation

    from missions.p000_capture.contract import Ellipsoid, surface_landmarks

    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=seed).as_matrix()
    c = rng.uniform(-3, 3, 3)
    pts, _ = surface_landmarks(axes, n)
    pts = pts @ rot.T + c + rng.normal(0, 0.02, (n, 3))
    idx = rng.permutation(n)[: int(outliers * n)]
    pts[idx] = c + rng.uniform(-6, 6, (len(idx), 3))
    return pts, Ellipsoid(c, rot, axes)


def bench_fits(fits: int, outliers: float) -> dict[str, float]:
    """Median wall time [s] of a cold GNC-TLS fit and of a track update, half case (i), half case (ii)
    shapes; and the fraction of cold fits whose sorted axes are within 2 %."""
    from missions.p000_capture.contract import Ellipsoid
    from agent.missions.p000_capture.gnc_tls import gnc_tls_fit, track_fit

    cold, track, ok = [], [], 0
    for s in range(fits):
        axes = np.array([2.6, 1.9, 1.4]) if s % 2 == 0 else np.array([4.0, 1.3, 1.0])
        pts, truth = synthetic(s, axes, outliers)
        t0 = time.perf_counter()
        fit = gnc_tls_fit(pts)
        cold.append(time.perf_counter() - t0)
        ok += bool(np.allclose(np.sort(fit.ellipsoid.semi_axes_m), np.sort(axes), rtol=0.02))
        prev = Ellipsoid(truth.centre_m + 0.05, truth.rotation, truth.semi_axes_m * 1.02)  # last period's estimate
        t0 = time.perf_counter()
        track_fit(pts, prev)
        track.append(time.perf_counter() - t0)
    return {"cold_fit_median_s": statistics.median(cold), "cold_fit_max_s": max(cold),
            "track_fit_median_s": statistics.median(track), "cold_within_2pct": ok / fits}


def bench_runs(scenario: str, duration: float) -> dict[str, float]:
    from deploy.launcher import MultiProcessRun, run_in_process
    from deploy.scenario import load_scenario

    sc = load_scenario(scenario).with_overrides(duration_s=duration)
    out = Path(tempfile.mkdtemp(prefix="swarmhil-bench-p000-"))
    t0 = time.perf_counter()
    res = MultiProcessRun(scenario, sc, out / "mp", "bench-p000-mp", progress=False,
                          overrides={"duration": duration}).execute()
    mp = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_in_process(sc, out / "ip", "bench-p000-ip")
    ip = time.perf_counter() - t0
    return {"steps": sc.steps, "agents": len(sc.ids), "multi_process_wall_s": mp,
            "multi_process_loop_s": res.summary.get("loop_wall_s", float("nan")), "in_process_wall_s": ip,
            "mp_over_ip": mp / ip, "out": str(out)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "deploy/scenarios/capture-20.toml"))
    ap.add_argument("--duration", type=float, default=550.0, help="simulated seconds (paper: 550)")
    ap.add_argument("--fits", type=int, default=20, help="synthetic GNC fits")
    ap.add_argument("--outliers", type=float, default=0.1, help="outlier fraction of the synthetic fits")
    ap.add_argument("--no-runs", action="store_true", help="only the GNC fits")
    a = ap.parse_args()
    if a.duration <= 0 or a.fits < 1 or not 0 <= a.outliers < 1:
        ap.error("--duration > 0, --fits >= 1, 0 <= --outliers < 1")
    res: dict[str, object] = {"loadavg_start": os.getloadavg()}
    res["fits"] = bench_fits(a.fits, a.outliers)
    f = res["fits"]
    print(f"GNC-TLS, 200 points, {a.outliers:.0%} outliers, {a.fits} fits: cold {f['cold_fit_median_s'] * 1e3:.0f} ms "
          f"median (max {f['cold_fit_max_s'] * 1e3:.0f} ms, {f['cold_within_2pct']:.0%} within 2 %), "
          f"track {f['track_fit_median_s'] * 1e3:.1f} ms median")
    if not a.no_runs:
        r = bench_runs(a.scenario, a.duration)
        res["runs"] = r
        print(f"{Path(a.scenario).name}: {r['agents']} agents, {r['steps']} steps: multi-process "
              f"{r['multi_process_wall_s']:.0f} s (plant loop {r['multi_process_loop_s']:.0f} s), in-process "
              f"{r['in_process_wall_s']:.0f} s, ratio {r['mp_over_ip']:.2f}")
    res["loadavg_end"] = os.getloadavg()
    print(json.dumps(res))


if __name__ == "__main__":
    main()
