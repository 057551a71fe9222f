"""Diagnostic experiment: the rendered camera + EKF swarm (sabatini-20-camera-filter.toml) with the
navigation's *values* replaced by the truth, the navigation's *choice of neighbours* kept.

    python examples/diagnostics/camera_oracle.py WHAT SEED [SEED ...] [--out FILE.json] [--set K=V ...]

WHAT is what the controller gets from the truth instead of the filter, for exactly the rows the
camera's navigation hands it (the same neighbours at the same steps):
  none      nothing (the scenario's own run, bit for bit)
  all       position and velocity of the true neighbour nearest the track's estimated position
  velocity  the true relative velocity only (the estimated position kept)
  position  the true relative position only (the estimated velocity kept)
  all+gated, all+untracked, all+gated+untracked
            `all`, and a row (truth) for each visible neighbour the control gate withheld / that has no track

Prints, per seed, the per-step weak connectivity, the total dV and the median distance between a
row's estimate and its matched true neighbour; with --out, writes [seed, connectivity, dV] rows
that pair with `swarmhil campaign deploy/scenarios/sabatini-20.toml` on the same seeds
(docs/camera-navigation.md). If `all` closes the gap to ideal sensing, the shortfall is in the
estimates' values; if not, in which neighbours are acted on and when.

An experiment, not a product feature: it wraps the batch hook's observation (deploy/batch.py
BatchHook._observe) in this process, so the law, the plant and the navigation are the scenario's.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from multiprocessing import Pool
from pathlib import Path

import numpy as np

SCENARIO = Path(__file__).resolve().parents[2] / "deploy" / "scenarios" / "sabatini-20-camera-filter.toml"


def truth_rows(batch, ctx, rows: np.ndarray, what: str, stats: dict, perceptions=None, max_sigma_m: float = 0.0,
               sigma_model: str = "mixture"):
    """The ObservationBatch with each row's position and/or velocity replaced by the truth of the
    neighbour nearest its estimated position (the observer itself excluded); with `+gated` in
    `what`, also a row (truth) for every visible neighbour whose track the control gate withheld,
    with `+untracked` for every visible neighbour with no output track. `stats` counts the visible
    pairs (ideal sensing's rule) by what the camera made of them."""
    from swarmhil.agent.controller import ObservationBatch
    from swarmhil.agent.perception import control_tracks
    from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

    vis = visibility_matrix(ctx.position_m, CameraGeometry(), ctx.alive)
    off = np.asarray(batch.offsets, dtype=np.int64)
    pos, vel = np.array(batch.rel_position_m, float).reshape(-1, 3), np.array(batch.rel_velocity_mps, float).reshape(-1, 3)
    ids = list(batch.neighbour_ids)
    new_pos, new_vel, new_ids, counts = [], [], [], []
    for i, j in enumerate(np.asarray(rows).tolist()):
        a, b = int(off[i]), int(off[i + 1])
        rel_p = ctx.position_m - ctx.position_m[j]
        rel_v = ctx.velocity_mps - ctx.velocity_mps[j]

        def match(est: np.ndarray) -> np.ndarray:
            d = np.linalg.norm(est[:, None, :] - rel_p[None, :, :], axis=2)
            d[:, j] = np.inf
            return np.argmin(d, axis=1)

        used = match(pos[a:b]) if b > a else np.zeros(0, dtype=np.int64)
        if b > a:
            stats["dist"].extend(np.linalg.norm(pos[a:b] - rel_p[used], axis=1).tolist())
        tracks = perceptions[j].tracks if perceptions is not None else []
        tracked = match(np.array([t.position_m for t in tracks]).reshape(-1, 3)) if tracks else np.zeros(0, dtype=np.int64)
        ctl = control_tracks(tracks, max_sigma_m, sigma_model)
        ctl_ids = {t.track_id for t in ctl}
        for t in tracks:
            if t.track_id not in ctl_ids:
                sd = np.sqrt(np.diagonal(np.asarray(t.covariance_m2)))
                key = ["a.da", "a.dl", "a.dex", "a.dey", "a.dix", "a.diy"][[0, 2, 3, 4, 5][int(np.argmax(sd[[0, 2, 3, 4, 5]]))]]
                stats.setdefault("gated_by", {}).setdefault(key, 0)
                stats["gated_by"][key] += 1
                stats.setdefault("gated_age", []).append(int(t.age_steps))
        ungated = match(np.array([t.position_m for t in ctl]).reshape(-1, 3)) if ctl else np.zeros(0, dtype=np.int64)
        vset, uset, tset = set(np.flatnonzero(vis[j]).tolist()), set(used.tolist()), set(tracked.tolist())
        gated = sorted((vset & tset) - set(ungated.tolist()) - uset)
        untracked = sorted(vset - tset - uset)
        stats["visible"] += len(vset)
        stats["used"] += len(vset & uset)
        stats["gated"] += len(gated)
        stats["untracked"] += len(untracked)
        stats["used_not_visible"] += len(uset - vset)
        rp, rv, ri = pos[a:b].copy(), vel[a:b].copy(), ids[a:b]
        if "all" in what or "position" in what:
            rp = rel_p[used]
        if "all" in what or "velocity" in what:
            rv = rel_v[used]
        extra = (gated if "+gated" in what else []) + (untracked if "+untracked" in what else [])
        extra = [k for k in extra if k not in uset]
        if extra:
            rp = np.concatenate([rp, rel_p[extra]])
            rv = np.concatenate([rv, rel_v[extra]])
            ri = list(ri) + [f"truth-{k}" for k in extra]
        new_pos.append(rp)
        new_vel.append(rv)
        new_ids.extend(ri)
        counts.append(len(rp))
    if not counts:
        return batch
    return ObservationBatch(step=batch.step, t_s=batch.t_s, u_rad=batch.u_rad, observers=batch.observers,
                            offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64), neighbour_ids=new_ids,
                            rel_position_m=np.concatenate(new_pos).reshape(-1, 3),
                            rel_velocity_mps=np.concatenate(new_vel).reshape(-1, 3))


def run_seed(args: tuple[int, str, list[str], float]):
    seed, what, sets, duration_s = args
    from swarmhil.dashboards.run_metrics import summary_with_metrics
    from swarmhil.deploy import batch as batch_mod
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    stats = {"dist": [], "visible": 0, "used": 0, "gated": 0, "untracked": 0, "used_not_visible": 0}
    observe = batch_mod.BatchHook._observe

    def wrapped(self, ctx, rows, observers, sense):
        batch = observe(self, ctx, rows, observers, sense)
        pers = self.perception.perceptions
        cfg = pers[0].cfg
        out = truth_rows(batch, ctx, rows, what, stats, pers, cfg["control_max_sigma_m"], cfg["control_sigma_model"])
        return batch if what == "none" else out  # "none": counted, flown as the scenario

    batch_mod.BatchHook._observe = wrapped
    sc = load_scenario(str(SCENARIO), sets).with_overrides(seed=seed, duration_s=duration_s)
    with tempfile.TemporaryDirectory() as tmp:
        run_in_process(sc, Path(tmp) / "run", f"oracle-{seed}", progress=False, record="truth")
        s = summary_with_metrics(Path(tmp) / "run")
    med = float(np.median(stats["dist"])) if stats["dist"] else float("nan")
    counts = {k: v for k, v in stats.items() if k not in ("dist", "gated_age")}
    ages = np.array(stats.get("gated_age", [0]))
    counts["gated_age_pct"] = np.percentile(ages, [10, 50, 90, 99]).tolist()
    return seed, float(s["metrics"]["connectivity"]["weakly_connected_fraction"]), float(s["delta_v_total_mps"]), med, counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["none", "all", "velocity", "position", "all+gated", "all+untracked", "all+gated+untracked"])
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--duration", type=float, default=86400.0)
    ap.add_argument("--set", dest="sets", action="append", default=[])
    a = ap.parse_args()
    with Pool(a.jobs, maxtasksperchild=1) as pool:  # a fresh process per run: the wrapped hook never outlives it
        rows = pool.map(run_seed, [(s, a.what, a.sets, a.duration) for s in a.seeds], chunksize=1)
    for seed, conn, dv, med, counts in rows:
        print(f"seed {seed}: weakly connected {100 * conn:.1f} % of the steps, dV {dv:.3f} m/s, "
              f"median |estimate - matched truth| {med:.2f} m; visible pairs {counts}")
    if a.out:
        a.out.write_text(json.dumps([r[:3] for r in rows]))


if __name__ == "__main__":
    main()
