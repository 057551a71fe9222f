"""Paired comparison of two campaigns over the same seeds (issue 16: the rendered camera + EKF
against ideal sensing, same initial conditions).

`swarmhil campaign-compare BASE OTHER` (deploy/cli_campaign.py). For every seed both campaigns ran:

- whether the two runs started from the same initial state (the resolved `[[spacecraft]]` ROE of
  each run's summary.json: a generated dispersion draws from `[run].seed`, `[dispersion]`, the
  camera and the orbit, so two scenarios that differ only in sensing draw the same swarm);
- each paired metric of both runs and the difference: fractions in percentage points
  (other - base), dV as the ratio other / base, closest approach and first split in metres and
  seconds (other - base);
- with both recordings kept, the per-step weak connectivity in time windows (the start-up transient
  against the rest of the run) and the mean number of visibility edges per step.

Over the seeds: mean, sample standard deviation and the 95 % confidence interval (Student t) of
each difference (the paired test: the seed-to-seed spread of the dispersion cancels), and, for the
per-step connectivity, how many seeds are within the tolerance and whether the confidence interval
of the mean difference is. Writes OUT/paired.parquet, OUT/paired.csv and OUT/paired.md.

`swarmhil campaign-compare BASE OTHER [OTHER2 ...]` (issue 36; `write_compare`): BASE against each
OTHER as above, and OUT/compare.json and OUT/compare.md with, per OTHER, the paired count of seeds
that split under OTHER and stay whole under BASE (whole: weakly connected at every step) and the
converse, and a headline over the seeds where BASE stays whole all run (a split there is OTHER's
sensing's): OTHER's mean and minimum per-step connectivity, how many seeds reach 97 %, the dV ratio;
beside it the same over all seeds.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from swarmhil.deploy.campaign import load_rows, mean_ci95, run_dir, write_table

WCF = "metrics.connectivity.weakly_connected_fraction"
# column, label, how the two values are compared: "pp" (other - base, x100), "ratio" (other / base), "diff"
PAIRED_METRICS: tuple[tuple[str, str, str], ...] = (
    (WCF, "weakly connected, per step [%]", "pp"),
    ("metrics.connectivity.orbit_union_weakly_connected_fraction", "weakly connected, union over each orbit [%]", "pp"),
    ("metrics.connectivity.weakly_connected_fraction_steady", "weakly connected, steady steps [%]", "pp"),
    ("delta_v_total_mps", "total dV [m/s]", "ratio"),
    ("metrics.closest_approach.all_pairs.distance_m", "closest approach, all pairs [m]", "diff"),
    ("metrics.connectivity.first_split_t_s", "first split [s] (none: never)", "diff"),
    ("metrics.connectivity.max_components", "max weakly connected components", "diff"),
)


class CompareError(ValueError):
    """Two campaign directories that cannot be compared (one clear line for the CLI)."""


def _campaign_meta(d: Path) -> dict[str, Any]:
    p = Path(d) / "campaign.json"
    if not p.is_file():
        raise CompareError(f"{d}: not a campaign directory (no campaign.json)")
    try:
        return json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CompareError(f"{p}: unreadable ({' '.join(str(exc).split())[:100]})") from None


def initial_roe(campaign_dir: Path, seed: int) -> np.ndarray | None:
    """(N, 6) initial ROE of the run of `seed` (its summary.json's resolved spacecraft), or None."""
    p = run_dir(Path(campaign_dir), seed) / "summary.json"
    try:
        cfg = json.loads(p.read_text())["config"]
        return np.array([s["roe_m"] for s in cfg["spacecraft"]], dtype=float)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def whole(row: dict[str, Any]) -> bool | None:
    """Whether a run's swarm stayed whole: weakly connected at every step (its per-step weakly
    connected fraction is exactly 1, i.e. it has no first split); None without the metric."""
    v = row.get(WCF)
    if v is None or not np.isfinite(float(v)):
        return None
    return float(v) == 1.0


def _pair_value(kind: str, a: Any, b: Any) -> float | None:
    if a is None or b is None:
        return None
    a, b = float(a), float(b)
    if not (np.isfinite(a) and np.isfinite(b)):
        return None
    if kind == "pp":
        return 100.0 * (b - a)
    if kind == "ratio":
        return b / a if a != 0 else None
    return b - a


def connectivity_windows(run_directory: Path, window_s: float) -> dict[str, Any] | None:
    """Per-step weak connectivity of a run in windows [k w, (k+1) w) of simulated time, from its
    recorded truth (plant/sensors.py: the same visibility digraph and components as the
    run's metrics), and the mean number of visibility edges per step; None without a recording."""
    mcap = Path(run_directory) / "run.mcap"
    if not mcap.is_file():
        return None
    from swarmhil.dashboards.truth_io import read_truth  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.sensors import CameraGeometry, visibility_series, weak_components  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    cam_cfg = json.loads((Path(run_directory) / "summary.json").read_text())["config"]["camera"]
    truth = read_truth(mcap)
    vis = visibility_series(truth.position_m, CameraGeometry(cam_cfg["detection_range_m"], cam_cfg["image_px"],
                                                             cam_cfg["focal_px"]), truth.alive)
    ncomp, _ = weak_components(vis)
    t = truth.t_s - truth.t_s[0]
    nwin = max(1, int(np.ceil(t[-1] / window_s - 1e-9)))
    k = np.minimum(np.floor(t / window_s).astype(int), nwin - 1)  # the final step joins the last window
    fractions = [float(np.mean(ncomp[k == i] == 1)) if np.any(k == i) else None for i in range(nwin)]
    return {"window_s": float(window_s), "fractions": fractions, "connected": ncomp == 1,
            "edges_mean": float(vis.sum(axis=(1, 2)).mean())}


def paired_rows(base_dir: Path, other_dir: Path, window_s: float | None = 7200.0) -> list[dict[str, Any]]:
    """One row per seed both campaigns finished (status ok): the paired metrics of both runs and
    their difference, whether they started from the same state, and (with the recordings) the
    connectivity per time window and the agreement of the two per-step connectivity series."""
    for d in (base_dir, other_dir):
        _campaign_meta(d)
    a = {r["seed"]: r for r in load_rows(base_dir) if r.get("status") == "ok"}
    b = {r["seed"]: r for r in load_rows(other_dir) if r.get("status") == "ok"}
    seeds = sorted(set(a) & set(b))
    rows = []
    for s in seeds:
        ra, rb = a[s], b[s]
        row: dict[str, Any] = {"seed": s}
        ia, ib = initial_roe(base_dir, s), initial_roe(other_dir, s)
        row["same_initial_state"] = (None if ia is None or ib is None
                                     else bool(ia.shape == ib.shape and np.array_equal(ia, ib)))
        for col, _label, kind in PAIRED_METRICS:
            row[f"base.{col}"], row[f"other.{col}"] = ra.get(col), rb.get(col)
            row[f"{kind}.{col}"] = _pair_value(kind, ra.get(col), rb.get(col))
        row["base.whole"], row["other.whole"] = whole(ra), whole(rb)
        if window_s:
            wa = connectivity_windows(run_dir(base_dir, s), window_s)
            wb = connectivity_windows(run_dir(other_dir, s), window_s)
            if wa is not None and wb is not None:
                row["base.edges_mean"], row["other.edges_mean"] = wa["edges_mean"], wb["edges_mean"]
                n = min(wa["connected"].size, wb["connected"].size)
                ca, cb = wa["connected"][:n], wb["connected"][:n]
                row["steps_base_only_connected"] = float(np.mean(ca & ~cb))  # fraction of steps
                row["steps_other_only_connected"] = float(np.mean(cb & ~ca))
                for i, (fa, fb) in enumerate(zip(wa["fractions"], wb["fractions"])):
                    row[f"window{i:02d}.base"], row[f"window{i:02d}.other"] = fa, fb
                row["window_s"] = float(window_s)
        rows.append(row)
    return rows


def paired_stats(rows: Sequence[dict[str, Any]], tolerance_pp: float = 2.0) -> dict[str, Any]:
    """Mean and 95 % CI over seeds of each paired difference; how many seeds have |per-step
    connectivity difference| <= tolerance_pp, and whether the CI of its mean lies within +-tolerance."""
    stats = {col: mean_ci95([r.get(f"{kind}.{col}") for r in rows]) for col, _l, kind in PAIRED_METRICS}
    d = [r.get(f"pp.{WCF}") for r in rows if r.get(f"pp.{WCF}") is not None]
    s = stats[WCF]
    return {"metrics": stats, "tolerance_pp": tolerance_pp, "seeds": len(rows),
            "seeds_within": int(sum(abs(x) <= tolerance_pp for x in d)),
            "ci_within": (s["ci95_low"] is not None and -tolerance_pp <= s["ci95_low"] and s["ci95_high"] <= tolerance_pp),
            "same_initial_state": all(r.get("same_initial_state") is True for r in rows) if rows else None}


def _f(v: Any, digits: int = 4) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _shown(kind: str, v: Any) -> Any:
    return None if v is None else (100.0 * float(v) if kind == "pp" else v)


def write_paired(base_dir: str | Path, other_dir: str | Path, out: str | Path, labels: Sequence[str] = ("base", "other"),
                 tolerance_pp: float = 2.0, window_s: float | None = 7200.0) -> dict[str, Any]:
    """OUT/paired.parquet, .csv (one row per seed) and OUT/paired.md; returns {"rows", "stats", "paths"}."""
    base_dir, other_dir, out = Path(base_dir), Path(other_dir), Path(out)
    ma, mb = _campaign_meta(base_dir), _campaign_meta(other_dir)
    if ma.get("duration_s") != mb.get("duration_s"):
        raise CompareError(f"the campaigns ran different durations ({ma.get('duration_s')} and {mb.get('duration_s')} s): "
                           f"their connectivity fractions are not comparable")
    rows = paired_rows(base_dir, other_dir, window_s)
    if not rows:
        raise CompareError(f"{base_dir} and {other_dir} have no seed that both ran successfully")
    st = paired_stats(rows, tolerance_pp)
    out.mkdir(parents=True, exist_ok=True)
    pq_path, csv_path = write_table(out, rows, name="paired", first=("seed", "same_initial_state"))
    la, lb = labels
    md = [f"# Paired campaigns: {lb} against {la}", "",
          f"{la}: `{ma.get('scenario')}` (--set {ma.get('sets') or 'none'}), `{base_dir}`; "
          f"{lb}: `{mb.get('scenario')}` (--set {mb.get('sets') or 'none'}), `{other_dir}`; "
          f"duration {ma.get('duration_s')} s; {len(rows)} seeds "
          f"({', '.join(str(r['seed']) for r in rows)}); same initial state in every pair: "
          f"{_f(st['same_initial_state'])}.", "",
          "## Per seed", "",
          f"| seed | same start | connected per step {la} / {lb} [%] | diff [pp] | orbit union {la} / {lb} [%] | diff [pp] "
          f"| total dV {la} / {lb} [m/s] | ratio | closest approach {la} / {lb} [m] | first split {la} / {lb} [h] |",
          "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    oun = "metrics.connectivity.orbit_union_weakly_connected_fraction"
    dv, ca, fs = "delta_v_total_mps", "metrics.closest_approach.all_pairs.distance_m", "metrics.connectivity.first_split_t_s"
    h = lambda v: None if v is None else float(v) / 3600.0  # noqa: E731
    for r in rows:
        md.append(f"| {r['seed']} | {_f(r['same_initial_state'])} "
                  f"| {_f(_shown('pp', r[f'base.{WCF}']), 3)} / {_f(_shown('pp', r[f'other.{WCF}']), 3)} "
                  f"| {_f(r[f'pp.{WCF}'], 3)} "
                  f"| {_f(_shown('pp', r[f'base.{oun}']), 3)} / {_f(_shown('pp', r[f'other.{oun}']), 3)} "
                  f"| {_f(r[f'pp.{oun}'], 3)} "
                  f"| {_f(r[f'base.{dv}'])} / {_f(r[f'other.{dv}'])} | {_f(r[f'ratio.{dv}'], 3)} "
                  f"| {_f(r[f'base.{ca}'], 3)} / {_f(r[f'other.{ca}'], 3)} "
                  f"| {_f(h(r[f'base.{fs}']), 3)} / {_f(h(r[f'other.{fs}']), 3)} |")
    md += ["", f"## Over the seeds ({lb} - {la}; dV: {lb} / {la})", "",
           "| metric | n | mean | 95 % CI of the mean | std | min | max |", "|---|---:|---:|---|---:|---:|---:|"]
    for col, label, kind in PAIRED_METRICS:
        s = st["metrics"][col]
        unit = {"pp": " difference [pp]", "ratio": " ratio", "diff": " difference"}[kind]
        ci = "-" if s["ci95_low"] is None else f"[{_f(s['ci95_low'], 3)}, {_f(s['ci95_high'], 3)}]"
        md.append(f"| {label}{unit} | {s['n']} | {_f(s['mean'], 3)} | {ci} | {_f(s['std'], 3)} "
                  f"| {_f(s['min'], 3)} | {_f(s['max'], 3)} |")
    md += ["", f"Per-step weak connectivity within {tolerance_pp:g} pp of {la}: {st['seeds_within']} of "
               f"{st['seeds']} seeds; the 95 % CI of the mean difference is "
               f"{'undefined (one seed)' if st['metrics'][WCF]['ci95_low'] is None else 'within' if st['ci_within'] else 'not within'}"
               f" +-{tolerance_pp:g} pp.", ""]
    win = [r for r in rows if "window_s" in r]
    if win:
        ws = win[0]["window_s"]
        md += [f"## Per-step weak connectivity in windows of {ws / 3600.0:g} h [%] ({la} / {lb})", "",
               "| seed | " + " | ".join(f"{i * ws / 3600.0:g}-{(i + 1) * ws / 3600.0:g} h" for i in range(_nwin(win)))
               + f" | steps connected only in {la} / only in {lb} [%] | visibility edges per step {la} / {lb} |",
               "|---:|" + "---:|" * (_nwin(win) + 2)]
        for r in win:
            cells = [f"{_f(_shown('pp', r.get(f'window{i:02d}.base')), 3)} / {_f(_shown('pp', r.get(f'window{i:02d}.other')), 3)}"
                     for i in range(_nwin(win))]
            md.append(f"| {r['seed']} | " + " | ".join(cells)
                      + f" | {_f(_shown('pp', r['steps_base_only_connected']), 3)} / "
                        f"{_f(_shown('pp', r['steps_other_only_connected']), 3)} "
                      + f"| {_f(r['base.edges_mean'], 3)} / {_f(r['other.edges_mean'], 3)} |")
        md.append("")
    md += ["Table: `paired.parquet` / `paired.csv` (one row per seed: `base.*`, `other.*` and the differences "
           "`pp.*` (percentage points), `ratio.*`, `diff.*`). deploy/campaign_compare.py.", ""]
    (out / "paired.md").write_text("\n".join(md))
    return {"rows": rows, "stats": st, "paths": (pq_path, csv_path, out / "paired.md")}


def _nwin(rows: Sequence[dict[str, Any]]) -> int:
    return max(sum(1 for k in r if k.startswith("window") and k.endswith(".base")) for r in rows)


# --- one BASE against several OTHERs: the paired splits and the headline (issue 36) ----------------------
HEADLINE_PCT = 97.0  # the headline counts the seeds whose per-step connectivity is at least this


def _pct(v: Any) -> float | None:
    return None if v is None or not np.isfinite(float(v)) else 100.0 * float(v)


def _block(rows: Sequence[dict[str, Any]], at_least_pct: float) -> dict[str, Any]:
    """Over `rows` (paired seeds): OTHER's and BASE's per-step weak connectivity [%] (mean, 95 % CI,
    min, max: `mean_ci95`), how many OTHER runs reach `at_least_pct` and stay whole, the difference
    [pp] and the dV ratio (mean_ci95 each)."""
    other = [_pct(r.get(f"other.{WCF}")) for r in rows]
    return {"n": len(rows), "seeds": [int(r["seed"]) for r in rows],
            "other_connectivity_pct": mean_ci95(other),
            "base_connectivity_pct": mean_ci95([_pct(r.get(f"base.{WCF}")) for r in rows]),
            "other_at_least": int(sum(v is not None and v >= at_least_pct for v in other)),
            "other_whole": int(sum(r.get("other.whole") is True for r in rows)),
            "diff_pp": mean_ci95([r.get(f"pp.{WCF}") for r in rows]),
            "dv_ratio": mean_ci95([r.get("ratio.delta_v_total_mps") for r in rows])}


def compare_aggregates(rows: Sequence[dict[str, Any]], at_least_pct: float = HEADLINE_PCT) -> dict[str, Any]:
    """What `campaign-compare` reports of one OTHER against BASE over the paired seeds (`paired_rows`):

    - `split_other_only` / `split_base_only`: the seeds whose swarm splits under OTHER and stays
      whole under BASE, and the converse (whole = weakly connected at every step, `whole`);
    - `headline`: over the seeds where BASE stays whole all run (any split there is OTHER's
      navigation's), OTHER's mean and min per-step connectivity, how many seeds reach
      `at_least_pct`, the dV ratio (`_block`);
    - `all_seeds`: the same over every paired seed."""
    known = [r for r in rows if r.get("base.whole") is not None and r.get("other.whole") is not None]
    so = [int(r["seed"]) for r in known if r["base.whole"] and not r["other.whole"]]
    sb = [int(r["seed"]) for r in known if r["other.whole"] and not r["base.whole"]]
    return {"seeds": [int(r["seed"]) for r in rows], "n": len(rows), "at_least_pct": float(at_least_pct),
            "base_whole": int(sum(r.get("base.whole") is True for r in rows)),
            "split_other_only": {"n": len(so), "seeds": so}, "split_base_only": {"n": len(sb), "seeds": sb},
            "headline": _block([r for r in rows if r.get("base.whole") is True], at_least_pct),
            "all_seeds": _block(rows, at_least_pct)}


def default_labels(others: Sequence[str | Path]) -> tuple[str, ...]:
    """BASE's and each OTHER's label when --label is not given: base, other (one OTHER, as before) or
    the OTHER directories' names (other1, other2, ... if two share a name)."""
    if len(others) == 1:
        return ("base", "other")
    names = [Path(o).name for o in others]
    if len(set(names)) < len(names) or "base" in names:
        names = [f"other{i + 1}" for i in range(len(others))]
    return ("base", *names)


def _ci_text(s: dict[str, Any], digits: int = 3, sign: bool = False) -> str:
    if s["mean"] is None:
        return "-"
    f = (lambda v: f"{v:+.{digits}g}") if sign else (lambda v: f"{v:.{digits}g}")
    return f(s["mean"]) + ("" if s["ci95_low"] is None else f" [{f(s['ci95_low'])}, {f(s['ci95_high'])}]")


def write_compare(base_dir: str | Path, other_dirs: Sequence[str | Path], out: str | Path,
                  labels: Sequence[str] | None = None, tolerance_pp: float = 2.0, window_s: float | None = 7200.0,
                  at_least_pct: float = HEADLINE_PCT) -> dict[str, Any]:
    """BASE against each OTHER: the paired table of each (`write_paired`: OUT/paired.* with one OTHER,
    OUT/<label>/paired.* with several), then OUT/compare.json (the aggregates of `compare_aggregates`
    per OTHER, by label, with the paired stats; what claims read) and OUT/compare.md (the headline
    table, the all-seeds table and each seed's connectivity under every sensing).
    Returns {"compare": the JSON's content, "paired": {label: write_paired's result}, "paths"}."""
    base_dir, out = Path(base_dir), Path(out)
    labels = tuple(labels) if labels else default_labels(other_dirs)
    if len(labels) != len(other_dirs) + 1:
        raise CompareError(f"--label must be given {len(other_dirs) + 1} times (BASE, then each OTHER) or not at all")
    if len(set(labels)) != len(labels):
        raise CompareError(f"the labels must differ: {', '.join(labels)}")
    lbase = labels[0]
    mbase = _campaign_meta(base_dir)
    paired: dict[str, dict[str, Any]] = {}
    others: dict[str, dict[str, Any]] = {}
    for lab, od in zip(labels[1:], other_dirs):
        od = Path(od)
        dest = out if len(other_dirs) == 1 else out / lab
        res = write_paired(base_dir, od, dest, (lbase, lab), tolerance_pp, window_s)
        paired[lab] = res
        mo = _campaign_meta(od)
        others[lab] = {"dir": str(od), "scenario": mo.get("scenario"), "sets": mo.get("sets") or [],
                       "paired_table": str(res["paths"][0]), "paired_md": str(res["paths"][2]),
                       "same_initial_state": res["stats"]["same_initial_state"],
                       "seeds_within_tolerance": res["stats"]["seeds_within"],
                       "ci_within_tolerance": res["stats"]["ci_within"],
                       **compare_aggregates(res["rows"], at_least_pct),
                       "paired_stats": res["stats"]["metrics"]}
    doc = {"base": {"label": lbase, "dir": str(base_dir), "scenario": mbase.get("scenario"),
                    "sets": mbase.get("sets") or [], "duration_s": mbase.get("duration_s")},
           "at_least_pct": float(at_least_pct), "tolerance_pp": float(tolerance_pp), "others": others}
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.json").write_text(json.dumps(doc, indent=1, default=_json_float))
    (out / "compare.md").write_text("\n".join(_compare_md(doc, paired)))
    return {"compare": doc, "paired": paired, "paths": (out / "compare.json", out / "compare.md")}


def _json_float(v: Any) -> Any:
    return float(v) if isinstance(v, np.floating) else bool(v) if isinstance(v, np.bool_) else str(v)


def _compare_md(doc: dict[str, Any], paired: dict[str, dict[str, Any]]) -> list[str]:
    b, q = doc["base"], doc["at_least_pct"]
    lb = b["label"]
    md = [f"# {', '.join(doc['others'])} against {lb}", "",
          f"{lb}: `{b['scenario']}` (--set {b['sets'] or 'none'}), `{b['dir']}`; duration {b['duration_s']} s. "
          f"Whole: weakly connected at every step (per-step connectivity 100 %, no first split).", "",
          f"## Headline: the seeds where {lb} stays whole (a split there is the sensing's)", "",
          f"| sensing | seeds where {lb} stays whole | connected per step, mean [%] | min [%] | seeds >= {q:g} % "
          f"| seeds that stay whole | difference from {lb}, mean [95 % CI] [pp] | dV ratio, mean [95 % CI] |",
          "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for lab, o in doc["others"].items():
        h = o["headline"]
        c = h["other_connectivity_pct"]
        md.append(f"| {lab} | {h['n']} of {o['n']} | {_f(c['mean'])} | {_f(c['min'])} | {h['other_at_least']} of {h['n']} "
                  f"| {h['other_whole']} of {h['n']} | {_ci_text(h['diff_pp'], sign=True)} | {_ci_text(h['dv_ratio'])} |")
    md += ["", "## All paired seeds", "",
           f"| sensing | seeds | connected per step, mean [%] ({lb}) | min [%] | seeds >= {q:g} % "
           f"| difference from {lb}, mean [95 % CI] [pp] | dV ratio, mean [95 % CI] "
           f"| split only under it (seeds) | split only under {lb} (seeds) | same start |",
           "|---|---:|---:|---:|---:|---:|---:|---|---|---|"]
    for lab, o in doc["others"].items():
        a = o["all_seeds"]
        c, cb = a["other_connectivity_pct"], a["base_connectivity_pct"]
        sp = lambda d: f"{d['n']} ({', '.join(map(str, d['seeds'])) or 'none'})"  # noqa: E731
        md.append(f"| {lab} | {o['n']} | {_f(c['mean'])} ({_f(cb['mean'])}) | {_f(c['min'])} "
                  f"| {a['other_at_least']} of {o['n']} | {_ci_text(a['diff_pp'], sign=True)} | {_ci_text(a['dv_ratio'])} "
                  f"| {sp(o['split_other_only'])} | {sp(o['split_base_only'])} | {_f(o['same_initial_state'])} |")
    seeds = sorted({s for o in doc["others"].values() for s in o["seeds"]})
    by = {lab: {r["seed"]: r for r in res["rows"]} for lab, res in paired.items()}
    labs = list(doc["others"])
    md += ["", "## Per seed: connected per step [%] (* whole), dV ratio", "",
           f"| seed | {lb} | " + " | ".join(labs) + " | " + " | ".join(f"dV ratio {lab}" for lab in labs) + " |",
           "|---:|" + "---:|" * (1 + 2 * len(labs))]
    for s in seeds:
        rows = [by[lab].get(s) for lab in labs]
        first = next(r for r in rows if r is not None)
        cell = lambda r, side: "-" if r is None else (  # noqa: E731
            f"{_f(_pct(r.get(f'{side}.{WCF}')), 3)}{'*' if r.get(f'{side}.whole') else ''}")
        md.append(f"| {s} | {cell(first, 'base')} | " + " | ".join(cell(r, "other") for r in rows) + " | "
                  + " | ".join("-" if r is None else _f(r.get("ratio.delta_v_total_mps"), 3) for r in rows) + " |")
    md += ["", "Machine-readable: `compare.json` (per sensing, by label: `headline`, `all_seeds`, `split_other_only`, "
               "`split_base_only`, `paired_stats`); each sensing's paired table: `paired.md` / `paired.parquet`. "
               "deploy/campaign_compare.py.", ""]
    return md
