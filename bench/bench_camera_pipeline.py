"""CPU time per camera frame of the whole flight-software perception: render + blobs + navigation
(agent.nav.pipeline.VisionNav.step), with 1, 3, 6 and 12 neighbours in view on relative orbits.

What one agent spends every 10 s of simulated time in the rendered camera scenarios; times 20
agents x 8640 frames it is the floor of a 24 h run's CPU time. Neighbours: random ROE (a*da
within +-2 m, 120-480 m ahead, a*de and a*di 10-40 m), propagated with the flight ROE model; the
navigator keeps its tracks from frame to frame as in a run. Times are medians over frames of this
thread's CPU time (time.thread_time), reported for both render backends and both navigators, with
the EKF as configured in deploy/scenarios/sabatini-20-camera-filter.toml; "nav" is the navigator's
update alone. The code measured is the `agent` package Python imports (printed): with
PYTHONPATH=<another checkout> the same script times that code (before/after, docs/benchmarks.md).

    .venv/bin/python bench/bench_camera_pipeline.py [--frames 120] [--ekf-only]
"""
from __future__ import annotations

import argparse
import time
import tomllib
from pathlib import Path

import numpy as np

from swarmhil.agent.camera.model import R_CAM_FROM_LVLH
from swarmhil.agent.nav.pipeline import VisionNav
from swarmhil.agent.roe import roe_to_lvlh

A_M = 6878137.0
N_RADPS = float(np.sqrt(3.986004418e14 / A_M**3))
SCENARIO = Path(__file__).resolve().parent.parent / "deploy" / "scenarios" / "sabatini-20-camera-filter.toml"


def neighbours(rng: np.random.Generator, n: int) -> np.ndarray:
    roe = np.empty((n, 6))
    roe[:, 0] = rng.uniform(-2.0, 2.0, n)
    roe[:, 1] = rng.uniform(120.0, 480.0, n)
    mag_e, ang_e = rng.uniform(10.0, 40.0, n), rng.uniform(0, 2 * np.pi, n)
    roe[:, 2], roe[:, 3] = mag_e * np.cos(ang_e), mag_e * np.sin(ang_e)
    roe[:, 4], roe[:, 5] = mag_e * np.cos(ang_e), mag_e * np.sin(ang_e)  # parallel de, di (no crossing)
    return roe


def time_pipeline(n: int, frames: int, imaging: str, navigator: str, backend: str, params: dict) -> tuple[float, float]:
    """Median CPU seconds per frame of the whole step and of the navigator's update alone."""
    rng = np.random.default_rng(n)
    roe = neighbours(rng, n)
    vis = VisionNav(A_M, N_RADPS, imaging=imaging, navigator=navigator, backend=backend,
                    nav_params=params if navigator == "ekf" else None)
    rot = np.broadcast_to(np.eye(3), (n, 3, 3))
    cpu, nav_cpu = [], []
    update = vis.navigator.update

    def timed_update(*args):
        t = time.thread_time()
        out = update(*args)
        nav_cpu.append(time.thread_time() - t)
        return out

    vis.navigator.update = timed_update
    for k in range(frames):
        u = N_RADPS * 10.0 * k
        roe[:, 1] -= 1.5 * N_RADPS * roe[:, 0] * 10.0
        pos, _ = roe_to_lvlh(roe, u, N_RADPS)
        t0 = time.thread_time()
        vis.step(10.0 * k, u, pos @ R_CAM_FROM_LVLH.T, rot, k, np.zeros(3))
        cpu.append(time.thread_time() - t0)
    return float(np.median(cpu[5:])), float(np.median(nav_cpu[5:]))  # after the first frames (track creation, JIT)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--ekf-only", action="store_true", help="only the rendered EKF rows")
    args = ap.parse_args()
    params = tomllib.loads(SCENARIO.read_text()).get("nav", {}).get("params", {})
    backends = ["numpy"]
    try:
        import numba  # noqa: F401

        backends.append("numba")
    except ImportError:
        print("numba not installed: numpy backend only")
    print(f"EKF parameters from {SCENARIO.name}: {params}")
    import agent.nav.ekf

    print(f"navigator code: {agent.nav.ekf.__file__}")
    print(" imaging  navigator  backend  in view  ms/frame  nav ms/frame")
    rows = (("render", "ekf"),) if args.ekf_only else (("render", "ekf"), ("render", "rough"), ("exact", "rough"))
    for imaging, navigator in rows:
        for backend in (backends if imaging == "render" else ["numpy"]):
            for n in (1, 3, 6, 12):
                ms, nav_ms = (1e3 * t for t in time_pipeline(n, args.frames, imaging, navigator, backend, params))
                print(f"{imaging:>8} {navigator:>10} {backend:>8} {n:8d} {ms:9.3f} {nav_ms:13.3f}")


if __name__ == "__main__":
    main()
