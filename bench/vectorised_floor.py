"""The compute floor of a paper-002 scenario: one vectorised numpy loop, no nodes, no bus (issue 16).

    python bench/vectorised_floor.py [SCENARIO] [--duration 86400] [--repeats 3]

The same scenario as `swarmhil run --in-process` (the initial conditions, orbit, camera, actuator
limit and controller parameters of the scenario file), written here once more, on purpose
independently of the project's node code: the linear Keplerian ROE plant (exact ZOH), the
rel stimulus (range and square field of view along +y), and the behavioural DRE-gain controller
of paper 002 (collision avoidance / alignment / attraction) evaluated for every visible pair of
every spacecraft at once. Only the periodic DRE gain *tables* (data: missions/p002_sabatini/fsw/dre.py,
from the disk cache) and the scenario loader are shared. For `controller = "null"` (drift-20)
the controller is skipped. It prints the loop's wall time and the total dV, which must agree
with the in-process run of the same scenario (bench/bench_backbone.py checks it to round-off).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

MU = 3.986004418e14


def floor_run(sc, steps: int | None = None) -> dict:
    """Run the scenario's dynamics and (sabatini or null) control law, vectorised; returns timings and dV."""
    from swarmhil.missions.p002_sabatini.fsw.dre import gain_table
    from swarmhil.missions.p002_sabatini.fsw.sabatini import SabatiniParams

    steps = sc.steps if steps is None else steps
    dt = sc.step_s
    a_m = sc.orbit.semi_major_axis_m
    n = float(np.sqrt(MU / a_m**3))
    u0 = sc.orbit.u0_rad
    roe = np.array(sc.roe_m, float)
    N = len(roe)
    umax = float(sc.max_accel_mps2)
    cam = sc.camera
    tan_cam = (cam["image_px"] / 2.0) / cam["focal_px"]
    rng2 = cam["detection_range_m"] ** 2
    control = sc.controller == "sabatini"
    if control:
        p = SabatiniParams.from_dict(dict(sc.controller_params))
        tabs = [gain_table(a_m, sc.orbit.mean_motion_radps, q, r, p.dre_table_size).gain_per_s2
                for q, r in ((p.q_ca, p.r_ca_si), (p.q_al, p.r_al_si), (p.q_att, p.r_att_si))]
        G = np.stack(tabs)  # (3 behaviours, table, 3, 6)
        n_tab = G.shape[1]
        tan_fov = np.tan(np.radians(p.fov_half_angle_deg))
        d_att = p.attraction_fraction * p.d_max_m
        span = d_att - p.d_min_m
        on = np.array([p.enable_collision_avoidance, p.enable_alignment, p.enable_attraction], float)
    dv = np.zeros(N)
    wall0 = time.perf_counter()
    for k in range(steps):
        u = u0 + n * (k * dt)
        c, s = np.cos(u), np.sin(u)
        da, dl, dex, dey, dix, diy = roe.T
        pos = np.column_stack((da - dex * c - dey * s, dl + 2 * dex * s - 2 * dey * c, dix * s - diy * c))
        vel = n * np.column_stack((dex * s - dey * c, -1.5 * da + 2 * dex * c + 2 * dey * s, dix * c + diy * s))
        acc = np.zeros((N, 3))
        if control:
            rel = pos[None, :, :] - pos[:, None, :]  # r_k - r_j
            ahead = rel[..., 1]
            vis = ((ahead > 0) & (np.abs(rel[..., 0]) <= tan_cam * ahead) & (np.abs(rel[..., 2]) <= tan_cam * ahead)
                   & ((rel * rel).sum(-1) <= rng2))
            j, kk = np.nonzero(vis)
            if j.size:
                x, y, z = (pos[j] - pos[kk]).T  # the observer relative to the neighbour
                vx, vy, vz = ((vel[j] - vel[kk]) / n).T
                e = np.column_stack((4 * x + 2 * vy, y - 2 * vx, 3 * x * c + vx * s + 2 * vy * c,
                                     3 * x * s - vx * c + 2 * vy * s, z * s + vz * c, -z * c + vz * s))
                de, di = np.hypot(e[:, 2], e[:, 3]), np.hypot(e[:, 4], e[:, 5])
                dmin = np.abs(e[:, 1]) - 2 * de
                beh = np.where(dmin < p.d_min_m, 0, np.where(dmin > d_att, 2, 1))
                rng = np.sqrt(x * x + y * y + z * z)
                dmt = p.fov_margin * rng * tan_fov
                par = np.where(de * di > 1e-18, np.abs(e[:, 2] * e[:, 4] + e[:, 3] * e[:, 5]) / np.maximum(de * di, 1e-300), 0.0)
                bad = (di > dmt) | (de > dmt) | (di < p.d_min_trans_m) | (de < p.d_min_trans_m) | (par < p.parallel_min)
                corr = (beh == 0) | ((beh == 1) & bad)
                dirx = np.where(de > 1e-9, e[:, 2] / np.maximum(de, 1e-300), np.where(di > 1e-9, e[:, 4] / np.maximum(di, 1e-300), 1.0))
                diry = np.where(de > 1e-9, e[:, 3] / np.maximum(de, 1e-300), np.where(di > 1e-9, e[:, 5] / np.maximum(di, 1e-300), 0.0))
                ref = e.copy()
                safe = p.k_ecc * p.d_min_trans_m
                ref[corr, 2] = ref[corr, 4] = safe * dirx[corr]
                ref[corr, 3] = ref[corr, 5] = safe * diry[corr]
                ref[:, 0] = np.where(beh == 0, p.ca_da_offset_m, 0.0)
                ref[beh == 2, 2:6] = 0.0
                w = np.where(beh == 1, np.clip((d_att - dmin) / span, 0.0, 1.0), 1.0) * on[beh]
                xg = (u % (2 * np.pi)) / (2 * np.pi) * n_tab
                i0 = int(np.floor(xg)) % n_tab
                f = xg - np.floor(xg)
                g = (1 - f) * G[:, i0] + f * G[:, (i0 + 1) % n_tab]  # (3, 3, 6) at this u
                contrib = -w[:, None] * np.einsum("pij,pj->pi", g[beh], e - ref)
                np.add.at(acc, j, contrib)
        acc = np.clip(acc, -umax, umax)
        dv += np.sqrt((acc * acc).sum(1)) * dt
        # exact ZOH of the linear Keplerian ROE model over [u, u + n dt]
        um, h = u + 0.5 * n * dt, np.sin(0.5 * n * dt)
        dcos, dsin = 2 * np.sin(um) * h / n**2, 2 * np.cos(um) * h / n**2
        gam = np.array([[0, 2 * dt / n, 0], [-2 * dt / n, -1.5 * dt**2, 0], [dcos, 2 * dsin, 0],
                        [-dsin, 2 * dcos, 0], [0, 0, dsin], [0, 0, dcos]])
        drift = np.zeros_like(roe)
        drift[:, 1] = -1.5 * n * dt * roe[:, 0]  # Phi = I + A dt: dl drifts with da
        roe = roe + drift + acc @ gam.T
    wall = time.perf_counter() - wall0
    return {"loop_s": wall, "steps": steps, "agents": N, "dv_total_mps": float(dv.sum())}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", nargs="?", default=str(ROOT / "deploy/scenarios/sabatini-20.toml"))
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--repeats", type=int, default=1)
    a = ap.parse_args()
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(a.scenario)
    if a.duration is not None:
        sc = sc.with_overrides(duration_s=a.duration)
    runs = [floor_run(sc) for _ in range(a.repeats)]
    best = min(runs, key=lambda r: r["loop_s"])
    print(json.dumps({**best, "loop_s_all": [r["loop_s"] for r in runs], "scenario": sc.name}))


if __name__ == "__main__":
    main()
