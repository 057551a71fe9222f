"""Paper 002's sources: sabatini-20 runs (24 h, batch mode) and their metrics (dashboards/metrics.py).

Each source returns `compute_metrics(...).summary` flattened (`connectivity.max_components`, ...)
plus the few figures of docs/paper002-reproduction.md's "Results" that the summary does not hold,
computed here from the same SwarmMetrics and truth (times of settling, of the whole-run minimum,
who is isolated at the end).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from swarmhil.claims.runs import camera_of, run_truth, scenario


def flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """{'a': {'b': 1}} -> {'a.b': 1}; lists of identifiers become tuples."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = list(v) if isinstance(v, (list, tuple)) else v
    return out


def last_above(t_s: np.ndarray, x: np.ndarray, threshold: float) -> float:
    """The first time after which x stays <= threshold (t[0] if it always does, nan if it never settles)."""
    above = np.flatnonzero(x > threshold)
    if above.size == 0:
        return float(t_s[0])
    if above[-1] + 1 >= t_s.size:
        return float("nan")
    return float(t_s[above[-1] + 1])


def sabatini_metrics(name: str = "sabatini-20", sets: tuple[str, ...] = (), seed: int | None = None,
                     duration_s: float | None = None) -> dict[str, Any]:
    """One sabatini run's metrics, flattened, plus the extras of the Results table."""
    from swarmhil.dashboards.metrics import compute_metrics, relative_to_com

    sc = scenario(name, sets, seed, duration_s)
    truth = run_truth(sc)
    m = compute_metrics(truth, camera_of(sc))
    out = flatten(m.summary)
    t = m.t_s
    da = np.abs(relative_to_com(truth.roe_m, truth.alive)[:, :, 0]).max(axis=1)
    out["x.da_below_5m_t_s"] = last_above(t, da, 5.0)
    out["x.da_below_1m_t_s"] = last_above(t, da, 1.0)
    out["x.da_at_20h_m"] = float(da[int(np.argmin(np.abs(t - 20 * 3600.0)))])
    along = m.closest.along_track_m
    i = np.unravel_index(int(np.nanargmin(along)), along.shape)[0]
    out["x.along_track_min_whole_run_t_s"] = float(t[i])
    acc = m.accel_mps2
    out["x.accel_max_t_s"] = float(t[int(np.argmax(acc.max(axis=1)))])
    out["x.accel_above_1pct_last_t_s"] = float(t[np.flatnonzero(acc.max(axis=1) > 0.01 * acc.max())[-1]])
    vis_end = m.vis[-1]
    out["x.isolated_end"] = [truth.ids[j] for j in range(len(truth.ids))
                             if not vis_end[j].any() and not vis_end[:, j].any()]
    dv_end = m.delta_v_mps[-1]
    out["x.zero_dv"] = [truth.ids[j] for j in range(len(truth.ids)) if dv_end[j] == 0.0]
    out["x.dv_min_nonzero_mps"] = float(dv_end[dv_end > 0].min()) if (dv_end > 0).any() else 0.0
    orbit_split = m.n_components_orbit > 1
    after = t >= t[0] + out["connectivity.orbit_period_s"]
    out["x.orbit_union_split_for_good"] = bool(orbit_split[-1])
    out["x.orbit_union_always_connected"] = bool(not orbit_split[after].any())
    return out
