"""Diagnostic experiment: paper 002's swarm with ideal sensing, each neighbour acted on only after it
has been in view for HOLD seconds without a gap (a tracker's confirmation delay, nothing else).

    python examples/diagnostics/ideal_holdoff.py HOLD_S SEED [SEED ...] [--out FILE.json]

Prints, per seed, the per-step weak connectivity and the total dV of the 24 h in-process batch run;
with --out, writes [seed, connectivity, dV] rows (docs/camera-navigation.md, "When a neighbour is
acted on"). Pair them with `swarmhil campaign deploy/scenarios/sabatini-20.toml` on the same seeds.

An experiment, not a product feature: it wraps the law's pair step (`SabatiniController._step_pairs`)
in this process to drop the rows of neighbours seen for less than HOLD_S, so the law, its gains and
the plant are those of `sabatini-20.toml`. HOLD_S = 0 is that scenario's run, bit for bit.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from multiprocessing import Pool
from pathlib import Path

import numpy as np

SCENARIO = Path(__file__).resolve().parents[2] / "deploy" / "scenarios" / "sabatini-20.toml"


def held_back_batch(batch, first_seen: dict[tuple[str, str], float], hold_s: float):
    """The ObservationBatch without the (observer, neighbour) rows in view for less than hold_s;
    `first_seen` (updated) holds when each pair in view came into view."""
    from swarmhil.agent.controller import ObservationBatch

    off = np.asarray(batch.offsets, dtype=np.int64)
    keep = np.zeros(int(off[-1]), bool)
    seen = set()
    for i, obs in enumerate(batch.observers):
        for r in range(off[i], off[i + 1]):
            key = (obs, batch.neighbour_ids[r])
            seen.add(key)
            keep[r] = batch.t_s - first_seen.setdefault(key, batch.t_s) >= hold_s
    for key in [k for k in first_seen if k not in seen]:
        del first_seen[key]  # out of view: its clock starts again when it comes back
    counts = [int(keep[off[i]:off[i + 1]].sum()) for i in range(len(batch.observers))]
    return ObservationBatch(step=batch.step, t_s=batch.t_s, u_rad=batch.u_rad, observers=batch.observers,
                            offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
                            neighbour_ids=[n for n, k in zip(batch.neighbour_ids, keep) if k],
                            rel_position_m=np.asarray(batch.rel_position_m, float).reshape(-1, 3)[keep],
                            rel_velocity_mps=np.asarray(batch.rel_velocity_mps, float).reshape(-1, 3)[keep])


def run_seed(args: tuple[int, float]) -> tuple[int, float, float]:
    seed, hold_s = args
    from swarmhil.dashboards.run_metrics import summary_with_metrics
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario
    from swarmhil.missions.p002_sabatini.fsw import sabatini

    if hold_s > 0:
        pair_step, first_seen = sabatini.SabatiniController._step_pairs, {}
        sabatini.SabatiniController._step_pairs = lambda self, b: pair_step(self, held_back_batch(b, first_seen, hold_s))
    sc = load_scenario(str(SCENARIO)).with_overrides(seed=seed, duration_s=86400.0)
    with tempfile.TemporaryDirectory() as tmp:
        run_in_process(sc, Path(tmp) / "run", f"holdoff-{seed}", progress=False, record="truth")
        s = summary_with_metrics(Path(tmp) / "run")
    return seed, float(s["metrics"]["connectivity"]["weakly_connected_fraction"]), float(s["delta_v_total_mps"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("hold_s", type=float)
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    with Pool(a.jobs, maxtasksperchild=1) as pool:  # a fresh process per run: the wrapped law and its clocks never outlive it
        rows = pool.map(run_seed, [(s, a.hold_s) for s in a.seeds], chunksize=1)
    for seed, conn, dv in rows:
        print(f"seed {seed}: weakly connected {100 * conn:.1f} % of the steps, dV {dv:.3f} m/s")
    if a.out:
        a.out.write_text(json.dumps(rows))


if __name__ == "__main__":
    main()
