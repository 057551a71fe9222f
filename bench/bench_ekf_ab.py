"""The camera navigation filter before and after issue 16, in one invocation: CPU time per frame
of `EkfNavigator.update` (all tracks at once) against `PerTrackEkf` (bench/ekf_per_track.py, the
per-track filter it replaced, the same estimates bit for bit), on the same recorded blobs.

Blobs: rendered frames (numba backend) of 1, 2, 3, 6 and 12 neighbours on relative orbits, as in
bench/bench_camera_pipeline.py; the EKF as configured in deploy/scenarios/sabatini-20-camera-filter.toml.
The two navigators run alternately, `--repeats` times each; printed: the median per frame of each
repetition (this thread's CPU time, after the first 5 frames) and the ratio of the medians.

    .venv/bin/python bench/bench_ekf_ab.py [--frames 200] [--repeats 3]
"""
from __future__ import annotations

import argparse
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]  # this checkout's agent package, not an installed one
from bench_camera_pipeline import A_M, N_RADPS, SCENARIO, neighbours
from ekf_per_track import PerTrackEkf

from swarmhil.agent.camera.model import R_CAM_FROM_LVLH
from swarmhil.agent.nav import EkfConfig, EkfNavigator
from swarmhil.agent.nav.pipeline import VisionNav
from swarmhil.agent.roe import roe_to_lvlh


def recorded_blobs(n: int, frames: int) -> tuple[VisionNav, list]:
    rng = np.random.default_rng(n)
    roe = neighbours(rng, n)
    vis = VisionNav(A_M, N_RADPS, imaging="render", navigator="rough", backend="auto")
    rot = np.broadcast_to(np.eye(3), (n, 3, 3))
    out = []
    for k in range(frames):
        u = N_RADPS * 10.0 * k
        roe[:, 1] -= 1.5 * N_RADPS * roe[:, 0] * 10.0
        pos, _ = roe_to_lvlh(roe, u, N_RADPS)
        vis.step(10.0 * k, u, pos @ R_CAM_FROM_LVLH.T, rot, k, np.zeros(3))
        out.append((10.0 * k, u, vis.last_blobs))
    return vis, out


def median_ms(nav: EkfNavigator, frames: list) -> float:
    cpu = []
    for t, u, blobs in frames:
        t0 = time.thread_time()
        nav.update(t, u, blobs, np.zeros(3))
        cpu.append(time.thread_time() - t0)
    return 1e3 * float(np.median(cpu[5:]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    params = tomllib.loads(SCENARIO.read_text())["nav"]["params"]
    print(f"EKF parameters from {SCENARIO.name}: {params}")
    print("in view  per-track ms/frame (each repeat)   all-at-once ms/frame (each repeat)   ratio of medians")
    for n in (1, 2, 3, 6, 12):
        vis, frames = recorded_blobs(n, args.frames)
        cam, shape = vis.renderer.camera, vis.renderer.shape
        res: dict[str, list[float]] = {"old": [], "new": []}
        for _ in range(args.repeats):
            res["old"].append(median_ms(PerTrackEkf(cam, shape, A_M, N_RADPS, EkfConfig(**params)), frames))
            res["new"].append(median_ms(EkfNavigator(cam, shape, A_M, N_RADPS, EkfConfig(**params)), frames))
        old, new = (" ".join(f"{v:6.3f}" for v in res[k]) for k in ("old", "new"))
        print(f"{n:7d}  {old:>34}   {new:>34}   {np.median(res['old']) / np.median(res['new']):6.2f}")


if __name__ == "__main__":
    main()
