"""Why the swarm split, and each navigation layer against truth step by step (issue 36), from the
arrays of an analysed run (`analysis.RunNav`); no files.

**Splits.** The visibility digraph of each truth step is the plant's rule (plant/sensors.py: j sees
k within the detection range and inside j's square field of view about +y LVLH). A split is a
truth row t whose digraph has more than one weakly connected component while row t-1 had one. The
edges lost at the split are the directed edges j -> k present at t-1 whose ends lie in different
components at t: they held the components together and are all gone at t. Edges that crossed the
new partition earlier in the look-back window (`before_steps` rows) and had already gone are listed
too (`lost_at_split` false), each with the last row it was present. For each lost edge: why it went
(the truth geometry at the first row without it: `range`, `fov`, `behind`, `observer_dead`), and
what each side's navigation believed over the window and at the split row: the observer j about k
and the other end k about j. A side's belief at a row is the track of the observer associated with
the true neighbour (analysis.associate: the nearest true relative position to the track's estimate;
with several, the nearest), or none; with its estimate (LVLH position, velocity, ROE, 6x6 ROE
covariance and its 1-sigma), whether the controller acted on it (a behaviour decision on that track
at that step, with the behaviour, the ROE it used and the acceleration it contributed, also along
the line of sight) and its errors against the true relative
state of the recorded truth: range |r_hat| - |r|, position, velocity, a*da, a*dl (signed),
|a*de|, |a*di| (norms of the 2-vectors), NEES. Geometry of both the truth and the estimate: range
margin (detection range - range), range rate, and image position (u, v) [px] with its margin to the nearest
image edge (f (tan(half FOV) - max(|x|, |z|) / y), the same square FOV; negative: outside; none
behind the camera). With ideal `rel` sensing there are no tracks and a decision names the true id.

**Per step against truth** (`step_series`). A track row is false when its nearest true neighbour is
farther from its estimate than max(`FALSE_GATE_M`, `FALSE_GATE_FRACTION` x estimated range); the
others are matched. At each truth row: visible pairs (truth); visible pairs whose observer sent no telemetry at that
step (`no_telemetry`: the last truth row of a run, a dead or paused agent); the other visible pairs
with no matched track,
split into `lost` (the pair had one at the previous row: a lost track) and `missed` (it had none:
not detected or not confirmed yet); false track rows; duplicate tracks (matched tracks of j on a k
beyond the first); swaps (a matched row whose track's previous matched row was another true
neighbour); breaks (a pair matched at the previous row and at this one, by another track id: the
navigator dropped its track and started a new one on the same neighbour). Without any track in the
telemetry (ideal `rel` sensing) these counts are kept but mean nothing (`tracks_recorded` false). Errors per layer, count / median / max over the rows of the step: `tracks` (every
matched track the navigator output), `used` (the matched tracks the controller acted on: passed
[nav].control_max_sigma_m and decided on), `decisions` (the ROE of the observer relative to the
neighbour each behaviour decision used, against truth: analysis.decision_roe_errors; ROE only, a
decision carries no range or velocity).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmhil.dashboards.navreport.analysis import RunNav, truth_rows_of_steps
from swarmhil.plant.sensors import weak_components

FALSE_GATE_M = 20.0
FALSE_GATE_FRACTION = 0.1
BEFORE_STEPS = 10
MAX_EVENTS = 200  # events of each kind listed in the JSON (all counted)
MAX_SPLITS = 100  # splits with beliefs in the JSON (all listed)

TRACK_QUANTITIES = ("range_m", "position_m", "velocity_mps", "da_m", "dl_m", "de_m", "di_m", "nees")
DECISION_QUANTITIES = ("da_m", "dl_m", "de_m", "di_m")


def _f(x: Any) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _v(a: np.ndarray) -> list[float | None]:
    return [_f(x) for x in np.asarray(a, float).ravel()]


def false_rows(nav: RunNav, gate_m: float = FALSE_GATE_M, gate_fraction: float = FALSE_GATE_FRACTION) -> np.ndarray:
    """(R,) bool: track rows with no true neighbour within the gate (module docstring)."""
    est_range = np.linalg.norm(nav.rows.position_m, axis=1)
    gate = np.maximum(gate_m, gate_fraction * est_range)
    return (nav.err.neighbour < 0) | ~(nav.err.assoc_m <= gate)


def _stats(group: np.ndarray, values: np.ndarray, T: int) -> dict[str, np.ndarray]:
    """count, median, max of values per group (truth row), NaN where a group has none."""
    ok = (group >= 0) & np.isfinite(values)
    g, v = group[ok], values[ok]
    order = np.lexsort((v, g))
    g, v = g[order], v[order]
    count = np.bincount(g, minlength=T)[:T]
    start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    med, mx = np.full(T, np.nan), np.full(T, np.nan)
    has = count > 0
    med[has] = 0.5 * (v[start[has] + (count[has] - 1) // 2] + v[start[has] + count[has] // 2])
    mx[has] = v[start[has] + count[has] - 1]
    return {"count": count, "median": med, "max": mx}


def _track_quantities(nav: RunNav) -> dict[str, np.ndarray]:
    e = nav.err.roe_err_m
    return {"range_m": np.abs(np.linalg.norm(nav.rows.position_m, axis=1) - nav.err.range_m),
            "position_m": np.linalg.norm(nav.err.position_err_m, axis=1),
            "velocity_mps": np.linalg.norm(nav.err.velocity_err_mps, axis=1),
            "da_m": np.abs(e[:, 0]), "dl_m": np.abs(e[:, 1]), "de_m": np.hypot(e[:, 2], e[:, 3]),
            "di_m": np.hypot(e[:, 4], e[:, 5]), "nees": nav.err.nees}


@dataclass
class StepSeries:
    """Per truth row (T): the comparisons of the module docstring."""

    step: np.ndarray
    t_s: np.ndarray
    components: np.ndarray  # weakly connected components of the visibility digraph
    visible_pairs: np.ndarray
    no_telemetry: np.ndarray  # visible pairs whose observer sent no telemetry at that step (not counted below)
    missed: np.ndarray  # visible, no matched track now nor at the previous row
    lost: np.ndarray  # visible, no matched track now, one at the previous row
    false_tracks: np.ndarray
    duplicate_tracks: np.ndarray
    swaps: np.ndarray
    breaks: np.ndarray  # pairs matched at the previous row and now, under another track id
    layers: dict[str, dict[str, dict[str, np.ndarray]]]  # layer -> quantity -> count / median / max
    events: dict[str, list[dict[str, Any]]]  # first MAX_EVENTS lost tracks, swaps, false tracks
    event_counts: dict[str, int]
    false_gate: dict[str, float]
    tracks_recorded: bool = True  # False: no track in the telemetry (ideal sensing), the track counts mean nothing


def step_series(nav: RunNav, gate_m: float = FALSE_GATE_M, gate_fraction: float = FALSE_GATE_FRACTION) -> StepSeries:
    """Missed, lost, false, duplicate and swapped tracks and the errors of each layer per truth row."""
    truth, rows, err = nav.truth, nav.rows, nav.err
    vis = nav.vis if nav.vis is not None else np.zeros((truth.n_steps, truth.n_bodies, truth.n_bodies), bool)
    T, N = truth.n_steps, truth.n_bodies
    n_comp, _ = weak_components(vis)
    false = false_rows(nav, gate_m, gate_fraction)
    m = (err.truth_row >= 0) & ~false
    tr, j, k = err.truth_row[m], rows.observer[m], err.neighbour[m]
    tracked = np.zeros((T, N, N), dtype=bool)  # dense like the visibility series; the rest is kept sparse
    tracked[tr, j, k] = True
    # one row per (truth row, j, k) matched: the nearest of duplicate tracks
    key = (tr * N + j) * N + k
    near = np.lexsort((err.assoc_m[m], key))
    ukey, first, n_on_pair = np.unique(key[near], return_index=True, return_counts=True)
    pick = near[first]
    dup = np.bincount(ukey // (N * N), weights=n_on_pair - 1, minlength=T)[:T].astype(np.int64)
    reported = np.ones((T, N), dtype=bool)  # the observer sent telemetry at that step
    if rows.tm_step.size:
        reported[:] = False
        tmr = truth_rows_of_steps(truth, rows.tm_step)
        reported[tmr[tmr >= 0], rows.tm_observer[tmr >= 0]] = True
    silent = vis & ~reported[:, :, None]
    untracked = vis & ~tracked & reported[:, :, None]
    before = np.zeros_like(tracked)
    before[1:] = tracked[:-1]
    lost_mask = untracked & before
    missed_mask = untracked & ~before
    ok_rows = err.truth_row >= 0
    false_per_row = np.bincount(err.truth_row[ok_rows & false], minlength=T)[:T]
    # swaps among matched rows, in the order of each track's life
    idx = np.flatnonzero(m)
    order = idx[np.lexsort((rows.step[idx], rows.track[idx]))]
    same = rows.track[order][1:] == rows.track[order][:-1]
    changed = err.neighbour[order][1:] != err.neighbour[order][:-1]
    swap_rows = order[1:][same & changed]
    swap_prev = order[:-1][same & changed]
    swaps = np.bincount(err.truth_row[swap_rows], minlength=T)[:T]
    # breaks: the pair's (nearest) track at consecutive truth rows has another id
    p_tr, p_pair, p_code = tr[pick], j[pick] * N + k[pick], rows.track[m][pick]
    o = np.lexsort((p_tr, p_pair))
    p_tr, p_pair, p_code = p_tr[o], p_pair[o], p_code[o]
    brk = np.flatnonzero((p_pair[1:] == p_pair[:-1]) & (p_tr[1:] == p_tr[:-1] + 1) & (p_code[1:] != p_code[:-1])) + 1
    breaks = np.bincount(p_tr[brk], minlength=T)[:T]

    layers: dict[str, dict[str, dict[str, np.ndarray]]] = {}
    if rows.n:
        q = _track_quantities(nav)
        g_all = np.where(m, err.truth_row, -1)
        g_used = np.where(m & rows.used, err.truth_row, -1)
        layers["tracks"] = {name: _stats(g_all, v, T) for name, v in q.items()}
        layers["used"] = {name: _stats(g_used, v, T) for name, v in q.items()}
    if nav.decisions.step.size:
        d = nav.decision_err
        g_dec = truth_rows_of_steps(truth, nav.decisions.step)
        dq = {"da_m": np.abs(d[:, 0]), "dl_m": np.abs(d[:, 1]), "de_m": np.hypot(d[:, 2], d[:, 3]),
              "di_m": np.hypot(d[:, 4], d[:, 5])}
        layers["decisions"] = {name: _stats(g_dec, v, T) for name, v in dq.items()}

    ids = truth.ids
    names = rows.track_names
    events: dict[str, list[dict[str, Any]]] = {
        "lost_tracks": [{"step": int(truth.step[t]), "observer": ids[a], "neighbour": ids[b]}
                        for t, a, b in np.argwhere(lost_mask)[:MAX_EVENTS]],
        "swaps": [{"step": int(rows.step[r]), "track": names[rows.track[r]], "from": ids[err.neighbour[p]],
                   "to": ids[err.neighbour[r]]} for r, p in list(zip(swap_rows, swap_prev))[:MAX_EVENTS]],
        "breaks": [{"step": int(truth.step[p_tr[i]]), "observer": ids[p_pair[i] // N], "neighbour": ids[p_pair[i] % N],
                    "from": names[p_code[i - 1]], "to": names[p_code[i]]} for i in brk[:MAX_EVENTS]],
    }
    fr = np.flatnonzero(false)
    false_tracks: list[dict[str, Any]] = []
    for c in np.unique(rows.track[fr])[:MAX_EVENTS]:
        rr = fr[rows.track[fr] == c]
        false_tracks.append({"track": names[c], "first_step": int(rows.step[rr].min()), "last_step": int(rows.step[rr].max()),
                             "rows": int(rr.size), "used_rows": int(rows.used[rr].sum()),
                             "nearest_true_m_min": _f(np.nanmin(err.assoc_m[rr])) if np.isfinite(err.assoc_m[rr]).any() else None})
    events["false_tracks"] = false_tracks
    counts = {"lost_tracks": int(lost_mask.sum()), "swaps": int(swap_rows.size), "breaks": int(brk.size),
              "false_tracks": int(np.unique(rows.track[fr]).size), "false_track_rows": int(fr.size),
              "missed_pair_steps": int(missed_mask.sum()), "duplicate_track_rows": int(dup.sum()),
              "visible_pair_steps_without_telemetry": int(silent.sum())}
    return StepSeries(truth.step.copy(), truth.t_s.copy(), n_comp, vis.sum(axis=(1, 2)), silent.sum(axis=(1, 2)),
                      missed_mask.sum(axis=(1, 2)),
                      lost_mask.sum(axis=(1, 2)), false_per_row, dup, swaps, breaks, layers, events, counts,
                      {"gate_m": gate_m, "gate_fraction_of_estimated_range": gate_fraction}, rows.n > 0)


def step_summary(s: StepSeries) -> dict[str, Any]:
    """Totals of the per-step comparisons over the run and the worst step of each (nav_summary.json)."""
    out: dict[str, Any] = {"definitions": "dashboards/navreport/diagnosis.py", "false_gate": s.false_gate,
                           "tracks_recorded": s.tracks_recorded, "visible_pair_steps": int(s.visible_pairs.sum()),
                           **s.event_counts}
    for name in ("missed", "lost", "false_tracks", "duplicate_tracks", "swaps", "breaks"):
        v = getattr(s, name)
        out[f"steps_with_{name}"] = int(np.count_nonzero(v))
        out[f"worst_step_{name}"] = {"step": int(s.step[np.argmax(v)]), "count": int(v.max())} if v.size and v.max() > 0 else None
    layers: dict[str, Any] = {}
    for layer, qs in s.layers.items():
        layers[layer] = {}
        for name, st in qs.items():
            mx = st["max"]
            fin = np.isfinite(mx)
            layers[layer][name] = {"rows": int(st["count"].sum()),
                                   "median_of_step_medians": _f(np.nanmedian(st["median"])) if fin.any() else None,
                                   "max": _f(np.nanmax(mx)) if fin.any() else None,
                                   "worst_step": int(s.step[np.nanargmax(mx)]) if fin.any() else None}
    out["layers"] = layers
    return out


def step_series_json(s: StepSeries) -> dict[str, Any]:
    """The per-step arrays as lists (nav_steps.json)."""
    return {"definitions": "dashboards/navreport/diagnosis.py", "false_gate": s.false_gate,
            "tracks_recorded": s.tracks_recorded, "step": s.step.tolist(), "t_s": s.t_s.tolist(), "components": s.components.tolist(),
            "visible_pairs": s.visible_pairs.tolist(), "no_telemetry": s.no_telemetry.tolist(), "missed": s.missed.tolist(), "lost": s.lost.tolist(),
            "false_tracks": s.false_tracks.tolist(), "duplicate_tracks": s.duplicate_tracks.tolist(),
            "swaps": s.swaps.tolist(), "breaks": s.breaks.tolist(),
            "layers": {layer: {name: {k: (v.tolist() if k == "count" else _v(v)) for k, v in st.items()}
                               for name, st in qs.items()} for layer, qs in s.layers.items()},
            "events": s.events, "event_counts": s.event_counts}


# ---- splits -------------------------------------------------------------------------------------

def split_rows(vis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(truth rows of the splits, components per row, component labels per row): rows t >= 1 with one
    weakly connected component at t-1 and more at t."""
    n, labels = weak_components(vis)
    t = np.flatnonzero((n[1:] > 1) & (n[:-1] == 1)) + 1
    return t, n, labels


def _image(rel: np.ndarray, focal_px: float, half_px: float, tan_half: float) -> tuple[list[float] | None, float | None]:
    """Image position (u, v) [px] of a relative LVLH position and its margin to the nearest image edge
    [px] (plant rule: square FOV about +y; image x right = -z, y down = -x); None behind the camera."""
    x, y, z = (float(c) for c in rel)
    if not (np.isfinite(y) and y > 0):
        return None, None
    return [half_px - focal_px * z / y, half_px - focal_px * x / y], focal_px * (tan_half - max(abs(x), abs(z)) / y)


def _loss_cause(nav: RunNav, t: int, j: int, k: int) -> list[str]:
    """Why j did not see k at truth row t (the plant's rule, clause by clause)."""
    cam = nav.camera
    rel = nav.truth.position_m[t, k] - nav.truth.position_m[t, j]
    out = []
    if not nav.truth.alive[t, j]:
        out.append("observer_dead")
    if not rel[1] > 0:
        out.append("behind")
    elif max(abs(rel[0]), abs(rel[2])) > cam.tan_half_fov * rel[1]:
        out.append("fov")
    if np.linalg.norm(rel) > cam.detection_range_m:
        out.append("range")
    return out


class _Beliefs:
    """Look-ups of track rows and decisions by (truth row, observer, true neighbour)."""

    def __init__(self, nav: RunNav, wanted_rows: np.ndarray, false: np.ndarray) -> None:
        self.nav, self.false = nav, false
        rows, err, truth = nav.rows, nav.err, nav.truth
        N = truth.n_bodies
        sel = np.flatnonzero(np.isin(err.truth_row, wanted_rows) & (err.neighbour >= 0))
        self.tracks: dict[tuple[int, int, int], list[int]] = {}
        for r in sel:
            self.tracks.setdefault((int(err.truth_row[r]), int(rows.observer[r]), int(err.neighbour[r])), []).append(int(r))
        # decisions by (truth row, observer, neighbour name), the name a track id or a spacecraft id
        dec = nav.decisions
        drow = truth_rows_of_steps(truth, dec.step)
        self.decisions: dict[tuple[int, int, str], int] = {}
        for i in np.flatnonzero(np.isin(drow, wanted_rows)):
            self.decisions[(int(drow[i]), int(dec.observer[i]), dec.neighbour[i])] = int(i)
        self.N = N

    def _decision(self, t: int, j: int, name: str, los: np.ndarray) -> dict[str, Any] | None:
        """The controller's decision on this neighbour: behaviour, the ROE it used and its error, and the
        acceleration it contributed, also along the true line of sight to the neighbour (> 0: towards it)."""
        i = self.decisions.get((t, j, name))
        if i is None:
            return None
        dec = self.nav.decisions
        acc = dec.accel_mps2[i] if i < dec.accel_mps2.shape[0] else np.full(3, np.nan)
        return {"neighbour": name, "behaviour": dec.behaviour[i] if i < len(dec.behaviour) else None,
                "roe_jk_m": _v(dec.roe_jk_m[i]), "roe_jk_err_m": _v(self.nav.decision_err[i]),
                "accel_mps2": _v(acc), "accel_towards_neighbour_mps2": _f(acc @ los)}

    def entry(self, t: int, j: int, k: int) -> dict[str, Any]:
        nav, truth, cam = self.nav, self.nav.truth, self.nav.camera
        rows, err = nav.rows, nav.err
        half = cam.image_px / 2.0
        focal = half / cam.tan_half_fov
        rel = truth.position_m[t, k] - truth.position_m[t, j]
        rel_v = truth.velocity_mps[t, k] - truth.velocity_mps[t, j]
        rng = float(np.linalg.norm(rel))
        los = rel / rng if rng > 0 else np.full(3, np.nan)
        img, margin = _image(rel, focal, half, cam.tan_half_fov)
        out: dict[str, Any] = {
            "step": int(truth.step[t]), "t_s": float(truth.t_s[t]), "observer": truth.ids[j], "neighbour": truth.ids[k],
            "truly_visible": bool(nav.vis[t, j, k]) if nav.vis is not None else None,
            "truth": {"position_m": _v(rel), "velocity_mps": _v(rel_v),
                      "roe_m": _v(truth.roe_m[t, k] - truth.roe_m[t, j]), "range_m": _f(rng),
                      "range_rate_mps": _f(rel_v @ los),
                      "range_margin_m": _f(cam.detection_range_m - rng), "image_px": img, "fov_margin_px": _f(margin) if margin is not None else None}}
        cands = self.tracks.get((t, j, k), [])
        out["tracks_on_neighbour"] = len(cands)
        out["track"] = None
        out["decision"] = None
        if cands:
            r = min(cands, key=lambda c: err.assoc_m[c])
            est = rows.position_m[r]
            e_img, e_margin = _image(est, focal, half, cam.tan_half_fov)
            cov = rows.covariance_m2[r]
            e = err.roe_err_m[r]
            tid = rows.track_names[rows.track[r]].split("/", 1)[1]
            out["track"] = {
                "id": tid, "age_steps": int(rows.age_steps[r]), "used_by_controller": bool(rows.used[r]),
                "false": bool(self.false[r]), "association_m": _f(err.assoc_m[r]), "second_nearest_m": _f(err.second_m[r]),
                "position_m": _v(est), "velocity_mps": _v(rows.velocity_mps[r]), "roe_m": _v(rows.roe_m[r]),
                "sigma_roe_m": _v(np.sqrt(np.clip(np.diagonal(cov), 0, None))) if np.isfinite(cov).all() else None,
                "covariance_m2": [_v(c) for c in cov] if np.isfinite(cov).all() else None,
                "range_m": _f(np.linalg.norm(est)), "range_rate_mps": _f(rows.velocity_mps[r] @ est / np.linalg.norm(est)),
                "image_px": e_img, "fov_margin_px": _f(e_margin) if e_margin is not None else None,
                "range_err_m": _f(np.linalg.norm(est) - rng), "position_err_m": _f(np.linalg.norm(err.position_err_m[r])),
                "velocity_err_mps": _f(np.linalg.norm(err.velocity_err_mps[r])),
                "da_err_m": _f(e[0]), "dl_err_m": _f(e[1]), "de_err_m": _f(np.hypot(e[2], e[3])),
                "di_err_m": _f(np.hypot(e[4], e[5])), "roe_err_m": _v(e), "nees": _f(err.nees[r])}
            out["decision"] = self._decision(t, j, tid, los)
        else:  # ideal sensing: the decision names the spacecraft
            out["decision"] = self._decision(t, j, truth.ids[k], los)
        return out


def _verdict(entries: list[dict[str, Any]], last_row_step: int) -> dict[str, Any]:
    """What one side's navigation held at the last step the edge existed, and over the window."""
    at = next((e for e in entries if e["step"] == last_row_step), None)
    tracked = [e for e in entries if e["step"] <= last_row_step and e["track"] is not None]
    before = [e for e in entries if e["step"] <= last_row_step]
    used = [e for e in before if (e["track"] is not None and e["track"]["used_by_controller"]) or e["decision"] is not None]
    out: dict[str, Any] = {"steps_in_window": len(before), "steps_tracked": len(tracked), "steps_acted_on": len(used)}
    if at is not None:
        tr, dec = at["track"], at["decision"]
        out.update({"step": at["step"], "had_track": tr is not None,
                    "controller_acting": dec is not None, "behaviour": dec["behaviour"] if dec else None,
                    "true_range_m": at["truth"]["range_m"], "true_fov_margin_px": at["truth"]["fov_margin_px"]})
        if tr is not None:
            out.update({k: tr[k] for k in ("id", "range_m", "range_err_m", "fov_margin_px", "da_err_m", "de_err_m",
                                           "di_err_m", "velocity_err_mps", "nees", "false")})
            out["max_sigma_gained_roe_m"] = (max(tr["sigma_roe_m"][i] for i in (0, 2, 3, 4, 5))
                                             if tr["sigma_roe_m"] else None)
        elif dec is not None and None not in dec["roe_jk_err_m"]:  # ideal sensing: the ROE the decision used
            e = np.asarray(dec["roe_jk_err_m"], float)  # of j relative to k: a*da's sign turned to k relative to j
            out.update({"da_err_m": _f(-e[0]), "de_err_m": _f(np.hypot(e[2], e[3])), "di_err_m": _f(np.hypot(e[4], e[5]))})
    return out


def splits(nav: RunNav, before_steps: int = BEFORE_STEPS, gate_m: float = FALSE_GATE_M,
           gate_fraction: float = FALSE_GATE_FRACTION, max_splits: int = MAX_SPLITS) -> list[dict[str, Any]]:
    """Every split of the visibility digraph with its lost edges and both sides' beliefs (module docstring)."""
    if nav.vis is None or nav.camera is None or nav.truth.n_steps < 2:
        return []
    vis, truth = nav.vis, nav.truth
    rows_t, n_comp, labels = split_rows(vis)
    want = np.unique(np.concatenate([np.arange(max(0, t - before_steps), t + 1) for t in rows_t[:max_splits]]
                                    or [np.zeros(0, int)]))
    beliefs = _Beliefs(nav, want, false_rows(nav, gate_m, gate_fraction))
    out = []
    for i, t in enumerate(rows_t):
        t = int(t)
        lab = labels[t]
        comps = [[truth.ids[a] for a in np.flatnonzero(lab == c)] for c in range(int(n_comp[t]))]
        r0 = max(0, t - before_steps)
        cross = lab[:, None] != lab[None, :]
        window = vis[r0:t] & cross[None]
        edges = []
        for j, k in np.argwhere(window.any(axis=0)):
            j, k = int(j), int(k)
            last = r0 + int(np.flatnonzero(window[:, j, k]).max())
            e: dict[str, Any] = {"observer": truth.ids[j], "neighbour": truth.ids[k], "last_seen_step": int(truth.step[last]),
                                 "lost_at_split": last == t - 1, "cause": _loss_cause(nav, last + 1, j, k)}
            if i < max_splits:
                side_j = [beliefs.entry(r, j, k) for r in range(r0, t + 1)]
                side_k = [beliefs.entry(r, k, j) for r in range(r0, t + 1)]
                e["observer_view"] = _verdict(side_j, int(truth.step[last]))
                e["neighbour_view"] = _verdict(side_k, int(truth.step[last]))
                e["belief_observer"] = side_j
                e["belief_neighbour"] = side_k
            edges.append(e)
        edges.sort(key=lambda e: (not e["lost_at_split"], -e["last_seen_step"], e["observer"], e["neighbour"]))
        out.append({"step": int(truth.step[t]), "t_s": float(truth.t_s[t]), "components_before": 1,
                    "components": comps, "window_start_step": int(truth.step[r0]), "lost_edges": edges,
                    "detailed": i < max_splits})
    return out


def edge_line(split: dict[str, Any], e: dict[str, Any]) -> str:
    """One line of text on a lost edge: why it went and what the observer's navigation held."""
    v = e.get("observer_view", {})
    w = e.get("neighbour_view", {})
    head = (f"{e['observer']} -> {e['neighbour']}: last seen step {e['last_seen_step']}"
            f"{'' if e['lost_at_split'] else ' (before the split)'}, lost by {'+'.join(e['cause']) or '?'}")
    if not v:
        return head
    g = lambda x, d=3: "n/a" if x is None else f"{x:.{d}g}"  # noqa: E731
    if v.get("had_track"):
        seen = (f"track {v['id']}{' FALSE' if v.get('false') else ''}, "
                f"{'acted on (' + str(v['behaviour']) + ')' if v['controller_acting'] else 'not acted on'}; "
                f"range {g(v['true_range_m'], 4)} m (err {g(v['range_err_m'])}), FOV margin {g(v['true_fov_margin_px'])} px "
                f"(est {g(v['fov_margin_px'])}), err a.da {g(v['da_err_m'])} a.de {g(v['de_err_m'])} a.di {g(v['di_err_m'])} m, "
                f"max sigma {g(v['max_sigma_gained_roe_m'])} m")
    else:
        seen = (f"NO track ({'acted on by id' if v.get('controller_acting') else 'not acted on'}); "
                f"range {g(v.get('true_range_m'), 4)} m, FOV margin {g(v.get('true_fov_margin_px'))} px")
    back = (f"; {e['neighbour']} about {e['observer']}: "
            + (f"track {w['id']}" if w.get("had_track") else "no track")
            + (f", acted on ({w['behaviour']})" if w.get("controller_acting") else ""))
    return (f"{head}; {e['observer']} at step {v.get('step')}: {seen}; tracked {v['steps_tracked']}/{v['steps_in_window']}, "
            f"acted on {v['steps_acted_on']}/{v['steps_in_window']} steps of the window{back}")


def splits_summary(sp: list[dict[str, Any]]) -> dict[str, Any]:
    """Count of splits and the first few, for nav_summary.json."""
    return {"splits": len(sp), "split_steps": [s["step"] for s in sp[:MAX_EVENTS]],
            "lost_edges_at_first_split": [f"{e['observer']}->{e['neighbour']}" for e in sp[0]["lost_edges"]
                                          if e["lost_at_split"]] if sp else []}
