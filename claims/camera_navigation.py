"""docs/camera-navigation.md "The camera campaign against ideal sensing" (issue 36): paper 002's swarm
flown with the camera, over seeds, paired with ideal sensing.

One source per camera mode (tier `study`: 20 exact and 80 rendered camera runs of 24 h in batch mode, each
rendered 20 seeds about 7 min on 2 cores), three campaigns of the same
seeds and initial conditions, each `swarmhil campaign SCENARIO --seeds 20 --first-seed 0 --duration
86400 --record truth` (deploy/campaign.py), then `swarmhil campaign-compare` of ideal sensing against
both camera modes (deploy/campaign_compare.py `write_compare`, its compare.json):

- ideal: deploy/scenarios/sabatini-20.toml (batch mode);
- exact: sabatini-20-camera-exact.toml (the scene measured exactly: blob area and centroid, rough
  navigation);
- filter: sabatini-20-camera-filter.toml (rendered images, blobs, the EKF).

The claims: per camera mode its mean per-step weak connectivity, the paired difference from ideal
with its 95 % interval, the paired count of seeds that split under the camera and stay whole under
ideal (and the converse), over the seeds where ideal stays whole all day the camera's minimum and
mean connectivity and how many reach 97 %, and the ΔV ratio. The verdicts are the issue's targets
(`TARGETS`).

The campaign directories: a temporary directory by default (removed after); with
`SWARMHIL_CAMERA_CAMPAIGN_DIR=DIR` they are DIR/ideal, DIR/exact, DIR/filter and DIR/compare, kept,
and a seed already finished there is read, not run again (`run_campaign` resumes), so the three
campaigns can be run by hand first (the commands in `commands`) and the claims then read them.
`SWARMHIL_CAMPAIGN_JOBS` sets the runs at once (default: the CPU count).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from swarmhil.claims.model import Claim, Row, Source, Table, Tol, Values
from swarmhil.claims.runs import SCENARIOS

DOC = "docs/camera-navigation.md"
SEEDS = tuple(range(20))
DURATION_S = 86400.0
AT_LEAST_PCT = 97.0
BASE = ("ideal", "sabatini-20")
MODES = (("exact", "sabatini-20-camera-exact"), ("filter", "sabatini-20-camera-filter"))
# the targets per camera mode: |mean difference from ideal| <= pp; every seed where ideal
# stays whole at >= 97 % (None: not a target of that mode); mean dV ratio <= dv
TARGETS: dict[str, dict[str, float | None]] = {"exact": {"pp": 3.0, "at_least": AT_LEAST_PCT, "dv": 1.3},
                                               "filter": {"pp": 5.0, "at_least": None, "dv": 1.5}}
SOURCE = "p002.cam.campaign"  # the prefix of each mode's source: p002.cam.campaign.<mode>
# the seeds of each camera mode's campaign: exact blobs the twenty of SEEDS, the rendered camera eighty
# (its paired differences spread by tens of points from seed to seed, and a day of a swarm at the edge
# of a split amplifies the last bit of a floating-point kernel: the same code and setting gave means a
# point or two apart under two kernel sets of one machine; four times the seeds halve the interval)
FILTER_SEEDS = tuple(range(80))
MODE_SEEDS: dict[str, tuple[int, ...]] = {"exact": SEEDS, "filter": FILTER_SEEDS}
# the count of seeds that split only under the rendered camera moves with the floating-point kernels (a
# day at the edge of a split: eighty seeds gave 11 under the default kernels, 8 under OPENBLAS_CORETYPE=Haswell);
# the band holds both samples, and stays clear of zero
SPLIT_TOL: dict[str, Tol] = {"filter": Tol(abs=3.0)}
DIR_ENV, JOBS_ENV = "SWARMHIL_CAMERA_CAMPAIGN_DIR", "SWARMHIL_CAMPAIGN_JOBS"


def commands(out: str = "runs/cam36", seeds: Sequence[int] = SEEDS, duration_s: float = DURATION_S,
             modes: Sequence[tuple[str, str]] = MODES, jobs: int = 2) -> list[str]:
    """The `swarmhil` commands that make the campaigns and the comparison this source reads."""
    first, n = min(seeds), len(seeds)
    runs = [f"swarmhil campaign deploy/scenarios/{scen}.toml --seeds {n} --first-seed {first} --duration {duration_s:g} "
            f"--record truth --jobs {jobs} --out {out}/{label}" for label, scen in (BASE, *modes)]
    labels = " ".join(f"--label {lab}" for lab, _ in (BASE, *modes))
    return [*runs, f"swarmhil campaign-compare {out}/{BASE[0]} " + " ".join(f"{out}/{lab}" for lab, _ in modes)
            + f" {labels} --out {out}/compare"]


def campaign_result(compare: Mapping[str, Any]) -> dict[str, Any]:
    """The source's flat result from campaign-compare's compare.json content (`write_compare`)."""
    out: dict[str, Any] = {"seeds": None, "ideal.wc_pct": None, "ideal.whole": None}
    for lab, o in compare["others"].items():
        a, h = o["all_seeds"], o["headline"]
        out["seeds"] = o["n"] if out["seeds"] is None else min(out["seeds"], o["n"])
        out["ideal.wc_pct"] = a["base_connectivity_pct"]["mean"]
        out["ideal.whole"] = o["base_whole"]
        out |= {f"{lab}.seeds": o["n"], f"{lab}.ideal_wc_pct": a["base_connectivity_pct"]["mean"],
                f"{lab}.ideal_whole": o["base_whole"],
                f"{lab}.wc_pct": a["other_connectivity_pct"]["mean"], f"{lab}.wc_min_pct": a["other_connectivity_pct"]["min"],
                f"{lab}.diff_pp": a["diff_pp"]["mean"], f"{lab}.diff_lo_pp": a["diff_pp"]["ci95_low"],
                f"{lab}.diff_hi_pp": a["diff_pp"]["ci95_high"],
                f"{lab}.split_only": o["split_other_only"]["n"], f"{lab}.split_only_seeds": o["split_other_only"]["seeds"],
                f"{lab}.split_base_only": o["split_base_only"]["n"],
                f"{lab}.head_n": h["n"], f"{lab}.head_min_pct": h["other_connectivity_pct"]["min"],
                f"{lab}.head_mean_pct": h["other_connectivity_pct"]["mean"], f"{lab}.head_at_least": h["other_at_least"],
                f"{lab}.dv_ratio": a["dv_ratio"]["mean"], f"{lab}.dv_lo": a["dv_ratio"]["ci95_low"],
                f"{lab}.dv_hi": a["dv_ratio"]["ci95_high"], f"{lab}.head_dv_ratio": h["dv_ratio"]["mean"],
                f"{lab}.same_start": bool(o["same_initial_state"])}
    return out


def camera_campaign(seeds: Sequence[int] = SEEDS, duration_s: float = DURATION_S, out: str | Path | None = None,
                    modes: Sequence[tuple[str, str]] = MODES, jobs: int | None = None) -> dict[str, Any]:
    """Run (or, in a kept directory, resume and read) the campaigns of ideal sensing and each camera
    mode over `seeds` for `duration_s`, compare them (compare.json) and return `campaign_result`.
    Raises when a run failed or the pairs did not start from the same state."""
    from swarmhil.deploy.campaign import run_campaign
    from swarmhil.deploy.campaign_compare import write_compare

    out = out if out is not None else os.environ.get(DIR_ENV) or None
    jobs = jobs or int(os.environ.get(JOBS_ENV) or 0) or os.cpu_count() or 1
    with tempfile.TemporaryDirectory(prefix="claims-cam-") as tmp:
        d = Path(out) if out is not None else Path(tmp)
        for label, scen in (BASE, *modes):
            res = run_campaign(str(SCENARIOS / f"{scen}.toml"), list(seeds), d / label, duration_s=float(duration_s),
                               executor="local", jobs=jobs, record="truth", keep_recording=out is not None)
            bad = [f"seed {r['seed']}: {r.get('error')}" for r in res["rows"] if r.get("status") != "ok"]
            if bad:
                raise RuntimeError(f"{label} campaign ({d / label}): {len(bad)} runs failed: {'; '.join(bad)[:400]}")
        cmp_dir = d / "compare" if len(modes) != 1 else d / f"compare-{modes[0][0]}"
        cmp = write_compare(d / BASE[0], [d / lab for lab, _ in modes], cmp_dir,
                            (BASE[0], *[lab for lab, _ in modes]), at_least_pct=AT_LEAST_PCT)["compare"]
    res = campaign_result(cmp)
    not_same = [lab for lab, _ in modes if not res[f"{lab}.same_start"]]
    if not_same:
        raise RuntimeError(f"{', '.join(not_same)}: not every pair started from ideal's initial state")
    if res["seeds"] != len(seeds):
        raise RuntimeError(f"{res['seeds']} paired seeds of {len(seeds)}")
    return res


def camera_source(name: str = SOURCE, seeds: Sequence[int] = SEEDS, duration_s: float = DURATION_S,
                  modes: Sequence[tuple[str, str]] = MODES) -> Source:
    """The campaign as a claims source (seeds and duration are its parameters)."""
    return Source(name, "study", lambda _get: camera_campaign(seeds, duration_s, modes=modes),
                  " && ".join(commands("DIR", seeds, duration_s, modes)) + f" (or {DIR_ENV}=DIR: read, resumed)")


def source_of(m: str) -> str:
    """The claims source of camera mode `m`: its campaign paired with ideal sensing on its seeds."""
    return f"{SOURCE}.{m}"


SOURCES = [camera_source(source_of(m), MODE_SEEDS[m], modes=((m, scen),)) for m, scen in MODES]

AUTO = Tol(auto=True)
P = "p002.cam"


def _k(key: str) -> Callable[[Mapping[str, Any]], Any]:
    return lambda s: s[key]


def _head(m: str, key: str) -> Callable[[Mapping[str, Any]], Any]:
    """A headline figure, or "none" when ideal stays whole on no seed (the headline is empty)."""
    return lambda s: "none" if not s[f"{m}.head_n"] else s[key]


def _c(id_: str, key: str | Callable[[Mapping[str, Any]], Any], tol: Tol, what: str, fmt: str, source: str) -> Claim:
    return Claim(f"{P}.{id_}", source, _k(key) if isinstance(key, str) else key, tol, what, fmt)


def mode_claims(m: str) -> list[Claim]:
    """The claims of one camera mode (label `m` of its source's result), ideal's figures over its seeds."""
    src = source_of(m)
    return [
        _c(f"{m}-seeds", f"{m}.seeds", Tol(), f"{m}: paired seeds (same initial state in each pair)", "d", src),
        _c(f"{m}-ideal-wc", f"{m}.ideal_wc_pct", AUTO, f"{m}: ideal's per-step weak connectivity over its seeds [%]", ".1f",
           src),
        _c(f"{m}-ideal-whole", f"{m}.ideal_whole", Tol(), f"{m}: its seeds where ideal stays whole at every step", "d", src),
        _c(f"{m}-wc", f"{m}.wc_pct", AUTO, f"{m}: per-step weak connectivity, mean over the seeds [%]", ".1f", src),
        _c(f"{m}-diff", f"{m}.diff_pp", AUTO, f"{m}: paired difference from ideal, mean [pp]", "+.2f", src),
        _c(f"{m}-diff-lo", f"{m}.diff_lo_pp", AUTO, f"{m}: its 95 % CI, low [pp]", "+.2f", src),
        _c(f"{m}-diff-hi", f"{m}.diff_hi_pp", AUTO, f"{m}: its 95 % CI, high [pp]", "+.2f", src),
        _c(f"{m}-split", f"{m}.split_only", SPLIT_TOL.get(m, Tol()), f"{m}: seeds that split under it and stay whole under ideal",
           "d", src),
        _c(f"{m}-split-base", f"{m}.split_base_only", Tol(), f"{m}: seeds that split under ideal and stay whole under it",
           "d", src),
        _c(f"{m}-head-min", _head(m, f"{m}.head_min_pct"), AUTO, f"{m}: min per-step connectivity where ideal stays whole [%]", ".1f", src),
        _c(f"{m}-head-mean", _head(m, f"{m}.head_mean_pct"), AUTO, f"{m}: mean per-step connectivity where ideal stays whole [%]",
           ".1f", src),
        _c(f"{m}-head-97", f"{m}.head_at_least", Tol(), f"{m}: seeds at >= 97 % where ideal stays whole", "d", src),
        _c(f"{m}-dv", f"{m}.dv_ratio", AUTO, f"{m}: dV ratio to ideal, mean over the seeds", ".2f", src),
        _c(f"{m}-dv-lo", f"{m}.dv_lo", AUTO, f"{m}: its 95 % CI, low", ".2f", src),
        _c(f"{m}-dv-hi", f"{m}.dv_hi", AUTO, f"{m}: its 95 % CI, high", ".2f", src),
    ]


CLAIMS = [c for m, _ in MODES for c in mode_claims(m)]


def verdict(m: str) -> Callable[[Values], str]:
    """The issue's target of mode `m` (TARGETS) against its claims: 'met', or what misses. "Within N pp
    of ideal" is read one-sided, the camera's mean per-step connectivity at most N pp below ideal's:
    the target is that navigation keeps the swarm as connected as ideal sensing; a camera swarm that
    stays whole where the ideal one splits (the initial conditions' chaos, both ways) is not a miss."""
    t = TARGETS[m]

    def v(vals: Values) -> str:
        diff, dv = float(vals[f"{P}.{m}-diff"]), float(vals[f"{P}.{m}-dv"])
        miss = []
        if diff < -float(t["pp"]):  # type: ignore[arg-type]  # less connected than ideal by more than pp
            miss.append(f"{diff:+.1f} pp from ideal")
        empty = ""
        if t["at_least"] is not None:
            n = int(vals[f"{P}.{m}-ideal-whole"])
            below = n - int(vals[f"{P}.{m}-head-97"])
            if below > 0:
                miss.append(f"{below} of {n} seeds below {t['at_least']:g} %")
            if n == 0:
                empty = f" (ideal stays whole on no seed: the {t['at_least']:g} % target is not tested)"
        if dv > float(t["dv"]):  # type: ignore[arg-type]
            miss.append(f"ΔV x{dv:.2f}")
        split, whole = int(vals[f"{P}.{m}-split"]), int(vals[f"{P}.{m}-ideal-whole"])
        but = ""
        if not miss and split:  # the mean can hide a seed the navigation lost: say so beside "met"
            but = (f" ({split} of the {whole} seeds where ideal stays whole split under it at some step, all at "
                   f">= {t['at_least']:g} %)" if t["at_least"] is not None
                   else f"; but {split} of the {whole} seeds where ideal stays whole split under it")
        return ("met" if not miss else "not met: " + ", ".join(miss)) + but + empty

    return v


def _row(m: str, what: str) -> Row:
    q = f"{P}.{m}"
    return Row((what, f"{{{q}-seeds}}", f"{{{q}-wc}} % (ideal {{{q}-ideal-wc}} %)", f"{{{q}-diff}} [{{{q}-diff-lo}}, {{{q}-diff-hi}}]",
                f"{{{q}-split}} ({{{q}-split-base}})",
                f"{{{q}-ideal-whole}} of {{{q}-seeds}} seeds: min {{{q}-head-min}} %, mean {{{q}-head-mean}} %, "
                f"{{{q}-head-97}} at >= 97 %",
                f"{{{q}-dv}} [{{{q}-dv-lo}}, {{{q}-dv-hi}}]",
                "at most {pp:g} pp below ideal{al}; ΔV <= {dv:g}x".format(
                    pp=TARGETS[m]["pp"], dv=TARGETS[m]["dv"],
                    al="" if TARGETS[m]["at_least"] is None else f"; >= {TARGETS[m]['at_least']:g} % on every seed where "
                                                                  f"ideal stays whole")),
               verdict(m), params=("97",))


TABLES = [Table(
    "camera-campaign", DOC,
    ("camera (same seeds and initial state as ideal)", "seeds (24 h each)", "per-step weak connectivity, mean over the seeds",
     "difference from ideal [pp], mean [95 % CI]", "seeds split under it, whole under ideal (the converse)",
     "the seeds where ideal stays whole: the camera's per-step connectivity", "ΔV ratio to ideal, mean [95 % CI]",
     "target", "verdict"),
    (_row("exact", "exact blobs + rough navigation (`sabatini-20-camera-exact`)"),
     _row("filter", "rendered images + EKF (`sabatini-20-camera-filter`)")),
    measured=(1, 2, 3, 4, 5, 6), verdict_col=8,
    align=("---", "---:", "---:", "---:", "---:", "---", "---:", "---", "---"))]


# ---- the navigation layers, against truth, on one seed (the error the controller acts on) ----
LAYER_SEED, LAYER_DURATION_S = 0, 21600.0
# (label, scenario, --set overrides): the exact imaging with the paper's rough navigator and with the
# EKF, the rendered imaging with the rough navigator, with the EKF as shipped and with three other IMM settings (a
# weaker manoeuvre model; a faster one; a quiet level at the settled swarm's measured accelerations)
LAYER_CASES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("exact-rough", "sabatini-20-camera-exact", ()),
    ("exact-ekf", "sabatini-20-camera-filter", ('nav.imaging="exact"',)),
    ("render-rough", "sabatini-20-camera-rough", ()),
    ("render-ekf", "sabatini-20-camera-filter", ()),
    ("render-ekf-mixgate", "sabatini-20-camera-filter", ('nav.control_sigma_model="mixture"',)),
    ("render-ekf-m3e5", "sabatini-20-camera-filter", ("nav.params.manoeuvre_accel_sigma_mps2=3e-5",)),
    ("render-ekf-fast", "sabatini-20-camera-filter",
     ("nav.params.manoeuvre_accel_sigma_mps2=1e-4", "nav.params.quiet_sojourn_s=600.0", "nav.params.manoeuvre_sojourn_s=600.0")),
    ("render-ekf-q3", "sabatini-20-camera-filter",
     ("nav.params.accel_sigma_mps2=3e-6", "nav.params.manoeuvre_accel_sigma_mps2=1e-4")),
)
LAYER_SOURCE = "p002.cam.layers"


def layer_errors(run_dir: Path) -> dict[str, Any]:
    """Errors of the ROE the controller acted on (report-nav's association of every used track row
    with the true neighbour), a*da and a*di: median and 95th percentile of |error| [m]; the rms of
    the a*da error over its 1-sigma where the navigator gives a covariance (1 = consistent)."""
    import numpy as np

    from swarmhil.dashboards.navreport.analysis import analyse_run

    rn = analyse_run(run_dir)
    used = rn.rows.used & np.isfinite(rn.err.roe_err_m).all(axis=1)
    e = rn.err.roe_err_m[used]
    sig = np.sqrt(rn.rows.covariance_m2[used][:, 0, 0])
    ok = np.isfinite(sig) & (sig > 0)
    return {"da_med": float(np.median(np.abs(e[:, 0]))), "da_p95": float(np.percentile(np.abs(e[:, 0]), 95)),
            "di_med": float(np.median(np.hypot(e[:, 4], e[:, 5]))),
            "z_da": float(np.sqrt(np.mean((e[ok, 0] / sig[ok]) ** 2))) if ok.any() else "none",
            "rows": int(used.sum())}


def camera_layers(seed: int = LAYER_SEED, duration_s: float = LAYER_DURATION_S) -> dict[str, Any]:
    """Fly each LAYER_CASES case in-process with every packet recorded (the tracks and decisions are
    in the agents' telemetry) and return its layer errors and total dV, keys '<case>.<figure>'."""
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="claims-camlayers-") as tmp:
        for label, scen, sets in LAYER_CASES:
            sc = load_scenario(str(SCENARIOS / f"{scen}.toml"), list(sets)).with_overrides(seed=seed, duration_s=duration_s)
            rdir = Path(tmp) / label
            res = run_in_process(sc, rdir, f"camlayers-{label}", progress=False, record="all")
            out |= {f"{label}.{k}": v for k, v in layer_errors(rdir).items()}
            out[f"{label}.dv"] = float(res.summary["delta_v_total_mps"])
    return out


def _layer_command(label: str, scen: str, sets: Sequence[str]) -> str:
    s = "".join(f" --set '{x}'" for x in sets)
    return (f"swarmhil run deploy/scenarios/{scen}.toml --in-process --seed {LAYER_SEED} --duration {LAYER_DURATION_S:g}"
            f"{s} --out DIR/{label} && swarmhil report-nav DIR/{label} --out DIR/{label}-nav")


SOURCES.append(Source(LAYER_SOURCE, "study", lambda _get: camera_layers(),
                      " ; ".join(_layer_command(*c) for c in LAYER_CASES)))


def _layer_claims(label: str) -> list[Claim]:
    q = f"{P}.layer.{label}"
    return [
        Claim(f"{q}.da-med", LAYER_SOURCE, _k(f"{label}.da_med"), AUTO, f"{label}: median |a*da error| acted on [m]", ".3f"),
        Claim(f"{q}.da-p95", LAYER_SOURCE, _k(f"{label}.da_p95"), AUTO, f"{label}: p95 |a*da error| acted on [m]", ".2f"),
        Claim(f"{q}.di-med", LAYER_SOURCE, _k(f"{label}.di_med"), AUTO, f"{label}: median |a*di error| acted on [m]", ".3f"),
        Claim(f"{q}.z-da", LAYER_SOURCE, _k(f"{label}.z_da"), AUTO if not label.endswith("rough") else Tol(),
              f"{label}: rms of the a*da error over its 1-sigma (1 = consistent; none without covariance)", ".2f"),
        Claim(f"{q}.dv", LAYER_SOURCE, _k(f"{label}.dv"), AUTO, f"{label}: total dV of the swarm [m/s]", ".3f"),
    ]


CLAIMS += [c for label, _, _ in LAYER_CASES for c in _layer_claims(label)]

_LAYER_WHAT = {
    "exact-rough": "exact blobs + rough navigation (silhouette range, two-frame dynamics)",
    "exact-ekf": "exact blobs + EKF (the filter's settings as shipped)",
    "render-rough": "rendered images + rough navigation (`sabatini-20-camera-rough`)",
    "render-ekf": "rendered images + EKF, as shipped (`sabatini-20-camera-filter`)",
    "render-ekf-mixgate": "rendered + EKF, the control gate on the IMM mixture's 1-σ instead of the quiet model's",
    "render-ekf-m3e5": "rendered + EKF, manoeuvre model 3e-5 m/s²",
    "render-ekf-fast": "rendered + EKF, manoeuvre model 1e-4 m/s², mode sojourns 600 s",
    "render-ekf-q3": "rendered + EKF, quiet model 3e-6 m/s², manoeuvre model 1e-4 m/s²",
}


def _layer_row(label: str) -> Row:
    q = f"{P}.layer.{label}"
    return Row((_LAYER_WHAT[label], f"{{{q}.da-med}} / {{{q}.da-p95}}", f"{{{q}.di-med}}", f"{{{q}.z-da}}", f"{{{q}.dv}}"),
               params=("1e-4", "600", "3e-6", "3e-5"))


TABLES.append(Table(
    "camera-layers", DOC,
    ("navigation (seed 0, 6 h, the same initial state)", "a·δa error acted on, median / 95 % [m]",
     "a·δi error acted on, median [m]", "a·δa error ÷ its 1-σ, rms", "swarm ΔV [m/s]"),
    tuple(_layer_row(label) for label, _, _ in LAYER_CASES),
    measured=(1, 2, 3, 4), align=("---", "---:", "---:", "---:", "---:")))
