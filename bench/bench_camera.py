"""Median render + blob time per frame at 1080 x 1080 with 1, 5, 10, 20 spacecraft in view (issue 4).

Bodies in nominal attitude at 30-500 m, spread uniformly over the field of view (the swarm's
usual view: a few pixels to a few tens of pixels each). Goal: <= 0.2 ms per frame.
Times are medians of the CPU time of this thread (time.thread_time), which other processes on a
busy machine inflate less than wall time; the wall-time median is printed too. One run measures
both backends: numpy (the reference, default) and numba (compiled once and cached).

    .venv/bin/python bench/bench_camera.py [--frames 300]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from swarmhil.agent.blob import extract_blobs
from swarmhil.agent.camera import Camera, Renderer, SpacecraftShape


def scene_in_view(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    z = rng.uniform(30.0, 500.0, n)
    pos = np.stack((rng.uniform(-0.5, 0.5, n) * z, rng.uniform(-0.5, 0.5, n) * z, z), axis=1)
    return pos, np.broadcast_to(np.eye(3), (n, 3, 3))


def time_frames(rend: Renderer, n: int, frames: int, seed: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    cpu_r, cpu_b, wall = [], [], []
    for k in range(frames):
        pos, rot = scene_in_view(rng, n)
        w0, t0 = time.perf_counter(), time.thread_time()
        stacks = rend.render_rois(pos, rot, frame=k)
        t1 = time.thread_time()
        extract_blobs(stacks, rend.detector, backend=rend.backend)
        t2, w2 = time.thread_time(), time.perf_counter()
        cpu_r.append(t1 - t0)
        cpu_b.append(t2 - t1)
        wall.append(w2 - w0)
    return {"render": float(np.median(cpu_r)), "blob": float(np.median(cpu_b)), "total": float(np.median(np.add(cpu_r, cpu_b))), "wall": float(np.median(wall))}


def numpy_op_us() -> float:
    """CPU time of one tiny numpy operation: the machine's speed at the time of the run."""
    a = np.ones(8)
    t0 = time.thread_time()
    for _ in range(20000):
        a + a
    return (time.thread_time() - t0) / 20000 * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    args = ap.parse_args()
    backends = ["numpy"]
    try:
        import numba  # noqa: F401

        backends.append("numba")
    except ImportError:
        print("numba not installed: numpy backend only")
    print(f"tiny numpy op: {numpy_op_us():.2f} us (about 0.3-0.5 us on an idle machine)")
    print(f"{'backend':>8} {'in view':>8} {'render ms':>10} {'blob ms':>8} {'total ms':>9} {'wall ms':>8} {'/ goal':>7}")
    for backend in backends:
        rend = Renderer(Camera(), SpacecraftShape(), backend=backend)
        time_frames(rend, 5, 20, 99)  # warm-up (and JIT compilation)
        for n in (1, 5, 10, 20):
            t = time_frames(rend, n, args.frames, n)
            print(
                f"{backend:>8} {n:>8} {t['render'] * 1e3:>10.3f} {t['blob'] * 1e3:>8.3f} {t['total'] * 1e3:>9.3f} "
                f"{t['wall'] * 1e3:>8.3f} {t['total'] / 2e-4:>6.2f}x"
            )


if __name__ == "__main__":
    main()
