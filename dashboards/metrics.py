"""The metrics every run has, whatever its mission, computed from TRUTH arrays; and the hook
through which a mission adds its own (issue 25: a mission-neutral overview, each mission's metrics
in its room).

Everything here is a pure function over numpy arrays shaped (T steps, N spacecraft, ...), as read
by dashboards/truth_io.py; nothing uses what the agents believed. Definitions:

- Control: |a| of the command applied over each step, cumulative dV per spacecraft (paper 002
  Figs. 19-20, the plant's accounting).
- Closest approach: minimum distance of any pair at any time, with a cubic Hermite interpolation
  of the relative position between samples (positions and velocities at both ends); with a
  visibility series, also split into pairs in visibility (j sees k or k sees j at the start of
  the interval) and pairs not in visibility.
- Steady state: t >= steady_from_s (default: the last sixth of the run).

A mission's own metrics (paper 002's connectivity of the visibility digraph, pair ROE, separations
and parallelism: missions/p002_sabatini/report/metrics.py) come from a hook its room's report
registers, `register_mission_metrics(name, applies)`: `compute_metrics(truth, cam, config=...)`
runs every hook whose `applies(config)` holds for the run's resolved configuration (found like the
report sections, bus/discovery.py `import_role("report")`) and merges what it returns into the
summary (summary.json["metrics"]), the per-step table and metrics_series.npz.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from swarmhil.bus.discovery import import_role
from swarmhil.plant.sensors import CameraGeometry


# --- frames ----------------------------------------------------------------------------------------
def relative_to_com(x: np.ndarray, alive: np.ndarray | None = None) -> np.ndarray:
    """x (T, N, d) minus the swarm centre of mass (equal masses, alive spacecraft) at each step."""
    w = np.ones(x.shape[:2]) if alive is None else alive.astype(float)
    w = np.where(w.sum(axis=1, keepdims=True) > 0, w, 1.0)
    com = np.einsum("tn,tnd->td", w, x) / w.sum(axis=1)[:, None]
    return x - com[:, None, :]


# --- control ---------------------------------------------------------------------------------------
def accel_norm(accel_mps2: np.ndarray) -> np.ndarray:
    """(T, N) |a| of the command held over each step."""
    return np.linalg.norm(accel_mps2, axis=-1)


def delta_v_from_accel(accel_mps2: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """(T, N) cumulative sum of |a| dt (the plant's dV accounting), 0 at the first sample."""
    dt = np.diff(t_s)
    inc = accel_norm(accel_mps2[:-1]) * dt[:, None]
    return np.vstack([np.zeros((1, accel_mps2.shape[1])), np.cumsum(inc, axis=0)])


# --- closest approach ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Approach:
    distance_m: float
    pair: tuple[int, int]
    t_s: float

    def as_dict(self, ids: list[str]) -> dict[str, Any]:
        if not np.isfinite(self.distance_m):
            return {"distance_m": None, "pair": None, "t_s": None}
        return {"distance_m": float(self.distance_m), "pair": [ids[self.pair[0]], ids[self.pair[1]]],
                "t_s": float(self.t_s)}


def _hermite_min(p0: np.ndarray, v0: np.ndarray, p1: np.ndarray, v1: np.ndarray, h: np.ndarray,
                 substeps: int) -> tuple[np.ndarray, np.ndarray]:
    """Min |p(s)| and its s over s in [0, 1] of the cubic Hermite p(s) through (p0, v0), (p1, v1);
    arrays (..., 3), h (...,) interval length. Sampled at substeps+1 points then refined by a
    parabola through the best sample's squared distance and its neighbours'."""
    s = np.linspace(0.0, 1.0, substeps + 1)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    hh = h[..., None, None]
    p = (h00[:, None] * p0[..., None, :] + h10[:, None] * hh * v0[..., None, :]
         + h01[:, None] * p1[..., None, :] + h11[:, None] * hh * v1[..., None, :])
    d2 = np.einsum("...i,...i->...", p, p)  # squared distance: smooth, quadratic near a close pass
    i = np.argmin(d2, axis=-1)
    dmin = np.take_along_axis(d2, i[..., None], -1)[..., 0]
    im, ip = np.clip(i - 1, 0, substeps), np.clip(i + 1, 0, substeps)
    dm = np.take_along_axis(d2, im[..., None], -1)[..., 0]
    dp = np.take_along_axis(d2, ip[..., None], -1)[..., 0]
    curv = dm - 2 * dmin + dp
    inner = (i > 0) & (i < substeps) & (curv > 0)
    off = np.where(inner, 0.5 * (dm - dp) / np.where(inner, curv, 1.0), 0.0)
    dref = np.where(inner, dmin - 0.25 * (dm - dp) * off, dmin)
    return np.sqrt(np.clip(np.minimum(dref, dmin), 0.0, None)), (i + off) / substeps


def closest_approach_series(position_m: np.ndarray, velocity_mps: np.ndarray, t_s: np.ndarray,
                            vis: np.ndarray | None = None, substeps: int = 8) -> dict[str, np.ndarray]:
    """Per interval [t_k, t_k+1): the minimum pair distance and its pair and time, for all pairs
    and, when `vis` is given, separately for pairs in visibility at t_k (either direction) and
    pairs not in visibility. Returns arrays of length T-1 (NaN / -1 where no pair of that class).

    The interpolated minimum (`_hermite_min`) is computed only for the pairs that can hold an
    interval's minimum of a class (issue 16: about 1 in 20 pairs): a pair is left out when a
    lower bound of its interpolated distance exceeds the smallest endpoint distance of the class
    in that interval. The bound: on [0, 1] the Hermite weights give h00 + h01 = 1 (both in
    [0, 1]) and |h10|, |h11| <= 4/27, so |p(s)| >= m = (|p0| + |p1| - |p1 - p0|) / 2 - 4/27 h
    (|v0| + |v1|) and |p(s)| <= M = max(|p0|, |p1|) + 4/27 h (|v0| + |v1|); the sampled minimum of
    the squared distance is >= m^2, and the parabolic refinement lowers it by at most a quarter of
    the spread of the samples, so the result is >= sqrt(1.25 m^2 - 0.25 M^2) (with a margin for
    rounding). A pair left out therefore never is the minimum nor ties it: the series is the one
    of evaluating every pair (`closest_approach_series_all`), value for value
    (tests/test_metrics.py)."""
    return _closest_approach_series(position_m, velocity_mps, t_s, vis, substeps, prune=True)


def closest_approach_series_all(position_m: np.ndarray, velocity_mps: np.ndarray, t_s: np.ndarray,
                                vis: np.ndarray | None = None, substeps: int = 8) -> dict[str, np.ndarray]:
    """`closest_approach_series` with every pair evaluated (the reference its pruning is tested against)."""
    return _closest_approach_series(position_m, velocity_mps, t_s, vis, substeps, prune=False)


_BOUND_REL = 1e-9  # relative rounding margin of the pruning bounds (double rounding errors are ~1e-15)


def _closest_approach_series(position_m: np.ndarray, velocity_mps: np.ndarray, t_s: np.ndarray,
                             vis: np.ndarray | None, substeps: int, prune: bool) -> dict[str, np.ndarray]:
    T, N, _ = position_m.shape
    jj, kk = np.triu_indices(N, 1)
    out = {f"{c}_{f}": np.full(T - 1, np.nan if f != "pair" else -1.0)
           for c in ("all", "visible", "hidden") for f in ("distance_m", "t_s", "pair")}
    if N < 2 or T < 2:
        return out
    for t0 in range(0, T - 1, 256):
        sl = slice(t0, min(t0 + 256, T - 1))
        sl1 = slice(sl.start + 1, sl.stop + 1)
        p0 = position_m[sl][:, jj] - position_m[sl][:, kk]
        v0 = velocity_mps[sl][:, jj] - velocity_mps[sl][:, kk]
        p1 = position_m[sl1][:, jj] - position_m[sl1][:, kk]
        v1 = velocity_mps[sl1][:, jj] - velocity_mps[sl1][:, kk]
        h = np.broadcast_to((t_s[sl1] - t_s[sl])[:, None], p0.shape[:2])
        classes = {"all": np.ones(p0.shape[:2], dtype=bool)}
        if vis is not None:
            seen = vis[sl][:, jj, kk] | vis[sl][:, kk, jj]
            classes.update(visible=seen, hidden=~seen)
        if prune:
            d = np.full(p0.shape[:2], np.inf)
            s = np.zeros(p0.shape[:2])
            ti, pi = np.nonzero(_candidates(p0, v0, p1, v1, h, classes))
            d[ti, pi], s[ti, pi] = _hermite_min(p0[ti, pi], v0[ti, pi], p1[ti, pi], v1[ti, pi], h[ti, pi], substeps)
        else:
            d, s = _hermite_min(p0, v0, p1, v1, h, substeps)  # (t, P)
        tmin = t_s[sl][:, None] + s * h
        for c, mask in classes.items():
            dm = np.where(mask, d, np.inf)
            best = np.argmin(dm, axis=1)
            val = np.take_along_axis(dm, best[:, None], 1)[:, 0]
            ok = np.isfinite(val)
            out[f"{c}_distance_m"][sl] = np.where(ok, val, np.nan)
            out[f"{c}_t_s"][sl] = np.where(ok, np.take_along_axis(tmin, best[:, None], 1)[:, 0], np.nan)
            out[f"{c}_pair"][sl] = np.where(ok, best, -1)
    return out


def _candidates(p0: np.ndarray, v0: np.ndarray, p1: np.ndarray, v1: np.ndarray, h: np.ndarray,
                classes: dict[str, np.ndarray]) -> np.ndarray:
    """(t, P) bool: the pairs whose interpolated distance can be their class's minimum of the
    interval (bounds in `closest_approach_series`); NaN anywhere makes a pair a candidate."""
    norm = lambda a: np.sqrt(np.einsum("...i,...i->...", a, a))  # noqa: E731
    r0, r1 = norm(p0), norm(p1)
    wobble = (4.0 / 27.0) * h * (norm(v0) + norm(v1))
    m = np.maximum(0.5 * (r0 + r1 - norm(p1 - p0)) - wobble, 0.0)
    big = np.maximum(r0, r1) + wobble
    lb2 = 1.25 * m * m - 0.25 * big * big - _BOUND_REL * big * big
    lb = np.sqrt(np.maximum(lb2, 0.0))
    ub = np.minimum(r0, r1) * (1.0 + _BOUND_REL)  # the interpolated minimum is at most an endpoint's distance
    cand = np.zeros(p0.shape[:2], dtype=bool)
    for mask in classes.values():
        thr = np.fmin.reduce(np.where(mask, ub, np.inf), axis=1)  # NaN-ignoring
        cand |= mask & ~(lb > thr[:, None])
    return cand


def closest_approach(series: dict[str, np.ndarray], n_bodies: int, cls: str = "all",
                     window: np.ndarray | None = None) -> Approach:
    """The overall minimum of one class of `closest_approach_series`, optionally within a mask of intervals."""
    d = series[f"{cls}_distance_m"]
    if window is not None:
        d = np.where(window, d, np.nan)
    if d.size == 0 or np.all(np.isnan(d)):
        return Approach(float("inf"), (-1, -1), float("nan"))
    i = int(np.nanargmin(d))
    jj, kk = np.triu_indices(n_bodies, 1)
    p = int(series[f"{cls}_pair"][i])
    return Approach(float(d[i]), (int(jj[p]), int(kk[p])), float(series[f"{cls}_t_s"][i]))


# --- everything, for summary.json --------------------------------------------------------------------
def stats(x: np.ndarray, threshold: float | None = None) -> dict[str, Any]:
    """count, min, p01, p05, median, max of the finite values (and the fraction >= threshold)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"count": 0}
    out = {"count": int(x.size), "min": float(x.min()), "p01": float(np.percentile(x, 1)),
           "p05": float(np.percentile(x, 5)), "median": float(np.median(x)), "max": float(x.max())}
    if threshold is not None:
        out["fraction_ge_threshold"] = float(np.mean(x >= threshold))
        out["threshold"] = threshold
    return out


@dataclass
class MissionMetrics:
    """What a mission's metrics hook returns for one run."""

    summary: dict[str, Any]  # into summary.json["metrics"]: new keys added, a dict under a key the
    #                          mission-neutral summary has extends that dict (closest_approach)
    columns: dict[str, np.ndarray] = field(default_factory=dict)  # per-step columns of the metrics_series table (dashboards/frames.py)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)   # per-step arrays of metrics_series.npz (sweep, faults)
    detail: Any = None  # the mission's own series, for its report section


@dataclass(frozen=True)
class MetricsInput:
    """What a hook gets: the run's truth (dashboards.truth_io.TruthArrays), its camera, the steady
    window (T,) bool and the closest approach's sub-samples."""

    truth: Any
    cam: CameraGeometry
    steady: np.ndarray
    substeps: int


MetricsHook = Callable[[MetricsInput], MissionMetrics]
_HOOKS: dict[str, tuple[Callable[[dict[str, Any]], bool], MetricsHook]] = {}


def register_mission_metrics(name: str, applies: Callable[[dict[str, Any]], bool]) -> Callable[[MetricsHook], MetricsHook]:
    """A mission's report registers the metrics of its runs (`applies(config)` on the resolved
    configuration, {} for a recording without one), as it registers its section."""
    def deco(fn: MetricsHook) -> MetricsHook:
        _HOOKS[name] = (applies, fn)
        return fn

    return deco


def mission_metrics_for(config: dict[str, Any]) -> list[tuple[str, MetricsHook]]:
    """The hooks that apply to a run, by name (every room's report loaded first)."""
    import_role("report")
    return [(name, fn) for name, (applies, fn) in sorted(_HOOKS.items()) if applies(config)]


@dataclass
class SwarmMetrics:
    """All per-step series of a run (for the report) and the scalar summary (for summary.json)."""

    t_s: np.ndarray
    accel_mps2: np.ndarray  # (T, N) norm
    delta_v_mps: np.ndarray  # (T, N)
    approach: dict[str, np.ndarray]  # closest_approach_series, all pairs
    steady: np.ndarray  # (T,) bool, steady-state window
    summary: dict[str, Any]
    missions: dict[str, MissionMetrics] = field(default_factory=dict)  # by hook name

    def columns(self) -> dict[str, np.ndarray]:
        """The per-step table (dashboards/frames.py metrics_series): t_s, the missions' columns,
        total dV, largest |a|."""
        out = {"t_s": self.t_s}
        for m in self.missions.values():
            out.update(m.columns)
        out["delta_v_total_mps"] = self.delta_v_mps.sum(axis=1)
        out["accel_max_mps2"] = np.nanmax(self.accel_mps2, axis=1) if self.accel_mps2.size else np.zeros(self.t_s.size)
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """metrics_series.npz: t_s, the missions' arrays, total dV."""
        out = {"t_s": self.t_s}
        for m in self.missions.values():
            out.update(m.arrays)
        out["delta_v_total_mps"] = self.delta_v_mps.sum(axis=1)
        return out


def merge_summary(summary: dict[str, Any], extra: dict[str, Any]) -> None:
    """Add a mission's summary to the mission-neutral one: new keys, and the entries of a dict
    under a key both have (a mission may not overwrite a value)."""
    for key, value in extra.items():
        if key not in summary:
            summary[key] = value
        elif isinstance(summary[key], dict) and isinstance(value, dict) and not set(summary[key]) & set(value):
            summary[key].update(value)
        else:
            raise ValueError(f"mission metrics would overwrite summary[{key!r}]")


def compute_metrics(truth: Any, cam: CameraGeometry | None = None, steady_from_s: float | None = None,
                    substeps: int = 8, config: dict[str, Any] | None = None) -> SwarmMetrics:
    """Metrics of a run from its TruthArrays: the mission-neutral ones, then those of every mission
    hook that applies to `config` (the run's resolved configuration; None or {}: a recording
    without one, i.e. paper 002's). Steady state: t >= steady_from_s (default: the last sixth of
    the run, i.e. the last 4 h of 24 h; paper 002's da has settled before 20 h)."""
    cam = cam or CameraGeometry()
    t = truth.t_s
    ids = truth.ids
    N = len(ids)
    if steady_from_s is None:
        steady_from_s = t[0] + (t[-1] - t[0]) * 5.0 / 6.0
    steady = t >= steady_from_s
    acc = accel_norm(truth.accel_mps2)
    dv = truth.delta_v_mps
    appr = closest_approach_series(truth.position_m, truth.velocity_mps, t, None, substeps)
    steady_iv = steady[:-1]

    dv_tot = dv.sum(axis=1)
    total = float(dv_tot[-1])
    i_steady = int(np.argmax(steady))
    last_hour = t >= t[-1] - 3600.0
    i_hour = int(np.argmax(last_hour))
    reached = lambda f: float(t[int(np.argmax(dv_tot >= f * total))]) if total > 0 else 0.0  # noqa: E731
    summary: dict[str, Any] = {
        "definitions": "dashboards/metrics.py docstring; steady state = t >= steady_from_s",
        "steps": int(t.size), "t_start_s": float(t[0]), "t_end_s": float(t[-1]), "steady_from_s": float(steady_from_s),
        "control": {
            "delta_v_total_mps": total,
            "delta_v_per_spacecraft_mps": {s: float(v) for s, v in zip(ids, dv[-1])},
            "delta_v_max_spacecraft_mps": float(dv[-1].max()),
            "delta_v_total_at_steady_start_mps": float(dv_tot[i_steady]),
            "delta_v_in_steady_window_mps": float(total - dv_tot[i_steady]),
            "delta_v_steady_fraction": float((total - dv_tot[i_steady]) / total) if total > 0 else 0.0,
            "delta_v_last_hour_mps": float(total - dv_tot[i_hour]),
            "t_95pct_delta_v_s": reached(0.95), "t_99pct_delta_v_s": reached(0.99),
            "accel_max_mps2": float(acc.max()),
            "accel_max_per_spacecraft_mps2": {s: float(v) for s, v in zip(ids, acc.max(axis=0))},
            "accel_nonzero_fraction_steady": float(np.mean(acc[steady] > 0)),
        },
        "closest_approach": {
            "all_pairs": closest_approach(appr, N, "all").as_dict(ids),
            "all_pairs_steady": closest_approach(appr, N, "all", steady_iv).as_dict(ids),
            "interpolation": f"cubic Hermite between samples, {substeps} sub-samples, parabolic refinement "
                             "of the squared distance",
        },
    }
    m = SwarmMetrics(t_s=t, accel_mps2=acc, delta_v_mps=dv, approach=appr, steady=steady, summary=summary)
    given = MetricsInput(truth, cam, steady, substeps)
    for name, hook in mission_metrics_for(config or {}):
        m.missions[name] = mm = hook(given)
        merge_summary(summary, mm.summary)
    return m
