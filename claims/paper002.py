"""Paper 002 (docs/paper002-reproduction.md "Results"): sabatini-20, 24 h, ideal sensing and noise.

Sources: the 24 h in-process batch run of sabatini-20 (`swarmhil run deploy/scenarios/sabatini-20.toml
--in-process --record truth`), its noise sweep (`sensing.roe_noise_fraction` 0.1-0.35) and other
noise realisations on sabatini-20-explicit (seeds 11, 12); metrics by dashboards/metrics.py.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping

from swarmhil.claims.model import Claim, Row, Source, Table, Tol, Values
from swarmhil.claims.p002_source import sabatini_metrics

DOC = "docs/paper002-reproduction.md"
PAPER_DV_MPS = 11.42  # section 5, 20 spacecraft, ideal sensing
D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN = 100.0, 30.0, 0.8
NOISE = (0.1, 0.2, 0.3, 0.35)
SEEDS = (11, 12)  # other noise realisations on sabatini-20-explicit (seed 7 = sabatini-20's own)


def _noise_run(frac: float, name: str = "sabatini-20", seed: int | None = None) -> Callable[[Any], dict[str, Any]]:
    return lambda get: sabatini_metrics(name, (f"sensing.roe_noise_fraction={frac}",), seed)


def _noise_key(frac: float, seed: int | None = None) -> str:
    return f"p002.noise-{round(frac * 100)}" + ("" if seed is None else f"-seed{seed}")


_KEEP = ("control.delta_v_total_mps", "control.delta_v_last_hour_mps", "x.orbit_union_split_for_good",
         "x.orbit_union_always_connected", "connectivity.weakly_connected_fraction",
         "connectivity.orbit_union_weakly_connected_fraction", "connectivity.components_end",
         "connectivity.max_components", "closest_approach.visible_pairs.distance_m",
         "closest_approach.non_visible_pairs.distance_m")


def _sweep(get: Callable[[str], dict[str, Any]]) -> dict[str, Any]:
    """The noise sweep of Figs. 30-31: the figures of each case the Results table uses."""
    cases = {"0": get("p002.s20")} | {str(f): get(_noise_key(f)) for f in NOISE}
    cases |= {f"{f}-seed{s}": get(_noise_key(f, s)) for f in (0.2, 0.3) for s in SEEDS}
    return {f"{case}.{k}": m[k] for case, m in cases.items() for k in _KEEP}


SOURCES = [
    Source("p002.s20", "quick", lambda get: sabatini_metrics("sabatini-20"),
           "swarmhil run deploy/scenarios/sabatini-20.toml --in-process --record truth (24 h, batch mode)"),
    *[Source(_noise_key(f), "all", _noise_run(f),
             f"the same with --set sensing.roe_noise_fraction={f}") for f in NOISE],
    *[Source(_noise_key(f, s), "all", _noise_run(f, "sabatini-20-explicit", s),
             f"sabatini-20-explicit.toml --seed {s} --set sensing.roe_noise_fraction={f}")
      for f in (0.2, 0.3) for s in SEEDS],
    Source("p002.noise", "all", _sweep, "the noise sweep and realisations above (derived)",
           uses=("p002.s20", *[_noise_key(f) for f in NOISE], *[_noise_key(f, s) for f in (0.2, 0.3) for s in SEEDS])),
]


def _k(key: str, scale: float = 1.0) -> Callable[[Mapping[str, Any]], Any]:
    """A claim read from a source's key, scaled (fraction -> %, s -> h)."""
    return lambda s: s[key] * scale if scale != 1.0 else s[key]


def _yes(key: str) -> Callable[[Mapping[str, Any]], str]:
    return lambda s: "yes" if s[key] else "no"


PCT, H = 100.0, 1.0 / 3600.0
AUTO = Tol(auto=True)  # max(3 x cross-kernel spread, half the last printed digit): claims/model.py resolve_tol
FRAC = AUTO  # percentage points
S20 = "p002.s20"


def _c(id_: str, key_or_fn: str | Callable[[Mapping[str, Any]], Any], tol: Tol, what: str, fmt: str = ".3g",
       scale: float = 1.0, source: str = S20) -> Claim:
    fn = _k(key_or_fn, scale) if isinstance(key_or_fn, str) else key_or_fn
    return Claim(id_, source, fn, tol, what, fmt)


def _pair(cls: str) -> Callable[[Mapping[str, Any]], str]:
    return lambda s: "-".join(s[f"closest_approach.{cls}.pair"])


def _dv_range_max(s: Mapping[str, Any]) -> float:
    return float(s["control.delta_v_max_spacecraft_mps"])


def _n_of(cases: tuple[str, ...], key: str, want: bool) -> Callable[[Mapping[str, Any]], int]:
    return lambda s: sum(bool(s[f"{c}.{key}"]) == want for c in cases)


C30 = ("0.3", "0.3-seed11", "0.3-seed12")
C20 = ("0.2", "0.2-seed11", "0.2-seed12")

CLAIMS = [
    # row 1: connectivity
    _c("p002.wc-always", _yes("connectivity.always_weakly_connected"), Tol(), "weakly connected at every step"),
    _c("p002.first-split-h", "connectivity.first_split_t_s", AUTO, "first split [h]", ".2f", H),
    _c("p002.wc-pct", "connectivity.weakly_connected_fraction", FRAC, "weakly connected steps [%]", ".1f", PCT),
    _c("p002.wc-steady-pct", "connectivity.weakly_connected_fraction_steady", FRAC,
       "weakly connected steps after 20 h [%]", ".1f", PCT),
    _c("p002.comp-max", "connectivity.max_components", Tol(), "most components at one step", "d"),
    _c("p002.comp-end", "connectivity.components_end", Tol(), "components at 24 h", "d"),
    _c("p002.largest-end", "connectivity.largest_component_end", Tol(), "largest component at 24 h", "d"),
    _c("p002.orbit-wc-pct", "connectivity.orbit_union_weakly_connected_fraction", FRAC,
       "orbit-union graph connected after the first orbit [%]", ".3g", PCT),
    # row 2: da
    _c("p002.da5-h", "x.da_below_5m_t_s", AUTO, "max |a da - com| below 5 m after [h]", ".1f", H),
    _c("p002.da1-h", "x.da_below_1m_t_s", AUTO, "max |a da - com| below 1 m after [h]", ".1f", H),
    _c("p002.da-20h-m", "x.da_at_20h_m", AUTO, "max |a da - com| at 20 h [m]", ".2f"),
    # row 3: along-track
    _c("p002.at-min", "closest_visible_steady.along_track_m.min", AUTO, "steady along-track min [m]", ".1f"),
    _c("p002.at-orbit-min", "closest_visible_steady.along_track_orbit_min_m.min", AUTO,
       "steady orbit-minimum a(|dl|-2|de|) min [m]", ".1f"),
    _c("p002.at-ge-pct", "closest_visible_steady.along_track_m.fraction_ge_threshold", FRAC,
       "steady samples >= 100 m [%]", ".3g", PCT),
    _c("p002.at-min-run", "closest_visible_whole_run.along_track_m.min", AUTO,
       "whole-run along-track min [m]", ".1f"),
    _c("p002.at-min-run-h", "x.along_track_min_whole_run_t_s", AUTO, "its time [h]", ".2f", H),
    # rows 4-5: transverse sizes
    *[c for p, key, name in (("ct", "cross_track_m", "a|di|"), ("rd", "radial_m", "a|de|")) for c in (
        _c(f"p002.{p}-min", f"closest_visible_steady.{key}.min", AUTO, f"steady {name} min [m]", ".1f"),
        _c(f"p002.{p}-med", f"closest_visible_steady.{key}.median", AUTO, f"steady {name} median [m]", ".1f"),
        _c(f"p002.{p}-ge-pct", f"closest_visible_steady.{key}.fraction_ge_threshold", FRAC,
           f"steady {name} >= 30 m [%]", ".1f", PCT))],
    # row 6: parallelism
    _c("p002.par-ge-pct", "closest_visible_steady.parallelism.fraction_ge_threshold", FRAC,
       "closest visible neighbour parallelism >= 0.8 [%]", ".1f", PCT),
    _c("p002.par-med", "closest_visible_steady.parallelism.median", AUTO, "its median", ".2f"),
    _c("p002.par-min", "closest_visible_steady.parallelism.min", AUTO, "its minimum", ".2g"),
    _c("p002.par-all-ge-pct", "visible_pairs_parallelism_steady.fraction_ge_threshold", FRAC,
       "all visible pairs parallelism >= 0.8 [%]", ".1f", PCT),
    # row 7: accelerations
    _c("p002.acc-max", "control.accel_max_mps2", AUTO, "max |a| [mm/s^2]", ".2f", 1e3),
    _c("p002.acc-max-mn", "control.accel_max_mps2", AUTO, "max thrust on 10 kg [mN]", ".2g", 1e4),
    _c("p002.acc-last-h", "x.accel_above_1pct_last_t_s", AUTO, "last |a| above 1 % of the max [h]", ".1f",
       H),
    _c("p002.sat", lambda s: "yes" if s["control.accel_max_mps2"] >= 1e-3 else "no", Tol(),
       "the 1 mm/s^2 limit reached"),
    # row 8: flat dV
    _c("p002.t95-h", "control.t_95pct_delta_v_s", AUTO, "95 % of dV by [h]", ".1f", H),
    _c("p002.t99-h", "control.t_99pct_delta_v_s", AUTO, "99 % of dV by [h]", ".1f", H),
    _c("p002.dv-steady", "control.delta_v_in_steady_window_mps", AUTO, "dV after 20 h [m/s]", ".2g"),
    _c("p002.dv-steady-pct", "control.delta_v_steady_fraction", AUTO, "dV after 20 h [% of total]",
       ".2f", PCT),
    _c("p002.dv-last-hour", "control.delta_v_last_hour_mps", AUTO, "dV in the last hour [m/s]", ".1g"),
    # row 9: total dV
    _c("p002.dv-total", "control.delta_v_total_mps", AUTO, "total dV of the 20 spacecraft [m/s]", ".2f"),
    _c("p002.dv-min-sc", "x.dv_min_nonzero_mps", AUTO, "smallest non-zero dV of one spacecraft [m/s]",
       ".3f"),
    _c("p002.dv-max-sc", _dv_range_max, AUTO, "largest dV of one spacecraft [m/s]", ".3f"),
    _c("p002.zero-dv", "x.zero_dv", Tol(), "spacecraft that spend nothing"),
    # row 10: final digraph
    _c("p002.sees-nobody-end", "connectivity.sees_nobody_end", Tol(), "spacecraft seeing nobody at 24 h"),
    _c("p002.isolated-end", "x.isolated_end", Tol(), "spacecraft isolated at 24 h"),
    # rows 11-12: closest approach
    _c("p002.ca-vis", "closest_approach.visible_pairs.distance_m", AUTO, "visible pairs [m]", ".1f"),
    _c("p002.ca-vis-pair", _pair("visible_pairs"), Tol(), "that pair"),
    _c("p002.ca-vis-h", "closest_approach.visible_pairs.t_s", AUTO, "its time [h]", ".2f", H),
    _c("p002.ca-vis-steady", "closest_approach.visible_pairs_steady.distance_m", AUTO,
       "visible pairs after 20 h [m]", ".1f"),
    _c("p002.ca-hid", "closest_approach.non_visible_pairs.distance_m", AUTO, "non-visible pairs [m]", ".1f"),
    _c("p002.ca-hid-pair", _pair("non_visible_pairs"), Tol(), "that pair"),
    _c("p002.ca-hid-h", "closest_approach.non_visible_pairs.t_s", AUTO, "its time [h]", ".2f", H),
    _c("p002.ca-hid-steady", "closest_approach.non_visible_pairs_steady.distance_m", AUTO,
       "non-visible pairs after 20 h [m]", ".1f"),
    # row 13: dV against the noise (Fig. 30)
    *[_c(f"p002.noise{round(f * 100)}-dv", f"{f}.control.delta_v_total_mps", AUTO,
         f"total dV at {round(f * 100)} % noise [m/s]", ".2f", source="p002.noise") for f in NOISE],
    _c("p002.noise35-ratio", lambda s: s["0.35.control.delta_v_total_mps"] / s["0.control.delta_v_total_mps"],
       AUTO, "dV at 35 % / ideal", ".2f", source="p002.noise"),
    _c("p002.noise35-last-hour", "0.35.control.delta_v_last_hour_mps", AUTO,
       "dV in the last hour at 35 % [m/s]", ".2g", source="p002.noise"),
    # row 14: integrity against the noise (Fig. 31)
    _c("p002.split30", _n_of(C30, "x.orbit_union_split_for_good", True), Tol(),
       "30 % realisations whose orbit-union graph ends split", "d", source="p002.noise"),
    _c("p002.split35", _n_of(("0.35",), "x.orbit_union_split_for_good", True), Tol(),
       "35 % runs whose orbit-union graph ends split", "d", source="p002.noise"),
    _c("p002.intact10", _n_of(("0.1",), "x.orbit_union_always_connected", True), Tol(),
       "10 % runs whose orbit-union graph stays connected", "d", source="p002.noise"),
    _c("p002.intact20", _n_of(C20, "x.orbit_union_always_connected", True), Tol(),
       "20 % realisations whose orbit-union graph stays connected", "d", source="p002.noise"),
]


# --- verdicts: computed from the values, against the paper's figures ------------------------------
def _v_connected(v: Values) -> str:
    step = "reproduced per step" if v["p002.wc-always"] == "yes" else "not reproduced per step"
    orbit = "reproduced orbit by orbit" if float(v["p002.orbit-wc-pct"]) >= 100.0 else "not reproduced orbit by orbit"
    return f"{step}; {orbit}"


def _ge(key: str, threshold: float, below: str = "not reproduced") -> Callable[[Values], str]:
    return lambda v: "reproduced" if float(v[key]) >= threshold else below


def _v_parallel(v: Values) -> str:
    p = float(v["p002.par-ge-pct"])
    return "reproduced" if p >= 100.0 else ("partly" if p >= 50.0 else "not reproduced")


def _v_accel(v: Values) -> str:  # mN level on ~10 kg: 0.1-10 mN, i.e. 0.01-1 mm/s^2
    return "reproduced" if 0.01 <= float(v["p002.acc-max"]) <= 1.0 else "not reproduced"


def _v_dv(v: Values) -> str:  # reproduced within a factor 1.25 of the paper's total (docs/claims.md)
    ratio = PAPER_DV_MPS / float(v["p002.dv-total"])
    if 0.8 <= ratio <= 1.25:
        return "reproduced"
    return f"not reproduced: {ratio:.1f}x {'lower' if ratio > 1 else 'higher'}; depends on the dispersion (below)"


def _v_final(v: Values) -> str:
    return "reproduced" if len(v["p002.sees-nobody-end"]) == 1 and not v["p002.isolated-end"] \
        else "not reproduced at that instant (see the gaps below)"


def _v_ca_vis(v: Values) -> str:
    """Against the row's own claim, d_min = 100 m along-track (Fig. 15); d_min_trans = 30 m is the
    radial / cross-track distance, below which a pair is unsafe."""
    d, steady = float(v["p002.ca-vis"]), float(v["p002.ca-vis-steady"])
    if d >= D_MIN_M:
        return "reproduced (>= d_min)"
    if d < D_MIN_TRANS_M:
        return "not reproduced: below d_min_trans"
    return ("partly: below d_min (above d_min_trans) in the start-up transient, >= d_min at steady state"
            if steady >= D_MIN_M else "not reproduced: below d_min, above d_min_trans")


def _v_ca_hid(v: Values) -> str:
    d = float(v["p002.ca-hid"])
    return "collision" if d < 1.0 else ("no collision, but below d_min" if d < D_MIN_M else "no collision")


def _v_noise_dv(v: Values) -> str:
    dv = [float(v["p002.dv-total"])] + [float(v[f"p002.noise{round(f * 100)}-dv"]) for f in NOISE]
    return "reproduced" if all(a < b for a, b in zip(dv, dv[1:])) else "not reproduced"


def _v_integrity(v: Values) -> str:
    lost30 = v["p002.split30"] == len(C30) and v["p002.split35"] == 1
    if not lost30:
        return "not reproduced"
    if v["p002.intact10"] == 1 and v["p002.intact20"] == len(C20):
        return "reproduced"
    if v["p002.intact10"] != 1:
        return "not reproduced: integrity already lost at 10 % noise (paper: kept up to 30 %)"
    return "partly: intact at 10 %, lost in some realisations at 20 % (paper: kept up to 30 %)"


HEADER = ("paper claim", "paper", "measured here", "verdict")
TABLES = [Table("paper002-results", DOC, HEADER, measured=(2,), verdict_col=3, rows=(
    Row(("swarm weakly connected throughout (Fig. 10)", "1 component, 24 h",
         "**per step: {p002.wc-always}.** First split at {p002.first-split-h} h; weakly connected in {p002.wc-pct} % "
         "of the steps ({p002.wc-steady-pct} % after 20 h), up to {p002.comp-max} components, {p002.comp-end} at the "
         "end (largest {p002.largest-end}). **Over each orbit (union of the last 95 min of digraphs):** one "
         "component {p002.orbit-wc-pct} % of the time after the first orbit"), _v_connected, ("20", "95")),
    Row(("da driven to zero in < 20 h (Fig. 12)", "< 20 h",
         "max over spacecraft of abs(a da - centre of mass) below 5 m after {p002.da5-h} h, 1 m after {p002.da1-h} h, "
         "{p002.da-20h-m} m at 20 h"), lambda v: "reproduced" if float(v["p002.da1-h"]) < 20.0 else "not reproduced",
        ("5", "1", "20")),
    Row(("along-track distance to the closest visible neighbour >= d_min = 100 m at steady state (Fig. 15)",
         ">= 100 m",
         "min {p002.at-min} m (instantaneous), orbit-minimum a(abs(dl)-2abs(de)) min {p002.at-orbit-min} m; "
         "{p002.at-ge-pct} % of samples >= 100 m (whole run: min {p002.at-min-run} m, at {p002.at-min-run-h} h)"),
        _ge("p002.at-min", D_MIN_M), ("2", "100")),
    Row(("out-of-plane size >= d_min_trans = 30 m at steady state (Fig. 16)", ">= 30 m",
         "a abs(di) min {p002.ct-min} m, median {p002.ct-med} m, {p002.ct-ge-pct} % of samples >= 30 m"),
        _ge("p002.ct-min", D_MIN_TRANS_M, "not reproduced (see below)"), ("30",)),
    Row(("radial size >= 30 m at steady state (Fig. 17)", ">= 30 m",
         "a abs(de) min {p002.rd-min} m, median {p002.rd-med} m, {p002.rd-ge-pct} % >= 30 m"),
        _ge("p002.rd-min", D_MIN_TRANS_M, "not reproduced (see below)"), ("30",)),
    Row(("parallelism >= 0.8 at steady state (Fig. 18)", ">= 0.8",
         "closest visible neighbour: {p002.par-ge-pct} % >= 0.8, median {p002.par-med}, min {p002.par-min}; "
         "all visible pairs: {p002.par-all-ge-pct} % >= 0.8"), _v_parallel, ("0.8",)),
    Row(("control accelerations of milli-newton thrusters for ~10 kg (Fig. 19)", "mN level",
         "max abs(a) {p002.acc-max} mm/s^2 ({p002.acc-max-mn} mN on 10 kg), none above 1 % of it after "
         "{p002.acc-last-h} h; 1 mm/s^2 limit reached: {p002.sat}"), _v_accel, ("10", "1")),
    Row(("flat dV at the end (Fig. 20)", "stationary",
         "95 % of the dV spent by {p002.t95-h} h, 99 % by {p002.t99-h} h; {p002.dv-steady} m/s "
         "({p002.dv-steady-pct} %) after 20 h, {p002.dv-last-hour} m/s in the last hour"),
        lambda v: "reproduced" if float(v["p002.dv-steady-pct"]) < 1.0 else "not reproduced", ("95", "99", "20")),
    Row(("total dV for 20 spacecraft (section 5)", "11.42 m/s",
         "**{p002.dv-total} m/s** ({p002.dv-min-sc}-{p002.dv-max-sc} m/s per spacecraft that fires; "
         "{p002.zero-dv} never sees anyone and spends 0)"), _v_dv, ("0",)),
    Row(("final digraph: nobody isolated, only the leader sees nobody (Fig. 11)", "1 node without out-edges",
         "at 24 h: {p002.sees-nobody-end} see nobody; isolated at that instant: {p002.isolated-end}"), _v_final,
        ("24",)),
    Row(("closest approach of visible pairs", "no collision, >= 100 m along-track",
         "{p002.ca-vis} m ({p002.ca-vis-pair} at {p002.ca-vis-h} h, transient); {p002.ca-vis-steady} m after 20 h"),
        _v_ca_vis, ("20",)),
    Row(("closest approach of non-visible pairs (not covered by the paper)", "-",
         "**{p002.ca-hid} m** ({p002.ca-hid-pair} at {p002.ca-hid-h} h, outside each other's field of view); "
         "{p002.ca-hid-steady} m after 20 h"), _v_ca_hid, ("20",)),
    Row(("dV grows with the navigation noise (Fig. 30)", 'grows "considerably"',
         "{p002.dv-total} / {p002.noise10-dv} / {p002.noise20-dv} / {p002.noise30-dv} / {p002.noise35-dv} m/s at "
         "0 / 10 / 20 / 30 / 35 % (x{p002.noise35-ratio} at 35 %); last hour {p002.noise35-last-hour} m/s at 35 % "
         "against {p002.dv-last-hour} m/s without noise"), _v_noise_dv, ("0", "10", "20", "30", "35")),
    Row(("integrity lost at 30 % noise (Figs. 30-31)", "upper bound 30 %, split at 35 %",
         "orbit-union graph split at the end in {p002.split30} of 3 realisations at 30 % and {p002.split35} of 1 at "
         "35 %; connected throughout in {p002.intact10} of 1 at 10 % and {p002.intact20} of 3 realisations at 20 %"),
        _v_integrity, ("3", "30", "1", "35", "10", "20")),
))]


# --- the noise tables ("Navigation noise"): the same runs, every column ---------------------------
def _case_claims(case: str, tag: str) -> list[Claim]:
    """The columns of one noisy run (case key of the p002.noise source, claim id tag)."""
    n = "p002.noise"
    return [
        _c(f"{tag}-dv", f"{case}.control.delta_v_total_mps", AUTO, f"{tag}: total dV [m/s]", ".2f", source=n),
        _c(f"{tag}-last-hour", f"{case}.control.delta_v_last_hour_mps", AUTO, f"{tag}: dV in the last hour [m/s]",
           ".2g", source=n),
        _c(f"{tag}-wc-pct", f"{case}.connectivity.weakly_connected_fraction", AUTO,
           f"{tag}: weakly connected steps [%]", ".1f", PCT, source=n),
        _c(f"{tag}-orbit-wc-pct", f"{case}.connectivity.orbit_union_weakly_connected_fraction", AUTO,
           f"{tag}: orbit-union connected after the first orbit [%]", ".3g", PCT, source=n),
        _c(f"{tag}-split", _yes(f"{case}.x.orbit_union_split_for_good"), Tol(),
           f"{tag}: orbit-union graph split at the end", source=n),
        _c(f"{tag}-comp-end", f"{case}.connectivity.components_end", Tol(), f"{tag}: components at 24 h", "d",
           source=n),
        _c(f"{tag}-comp-max", f"{case}.connectivity.max_components", Tol(), f"{tag}: most components", "d",
           source=n),
        _c(f"{tag}-ca-vis", f"{case}.closest_approach.visible_pairs.distance_m", AUTO,
           f"{tag}: closest approach, visible pairs [m]", ".1f", source=n),
        _c(f"{tag}-ca-hid", f"{case}.closest_approach.non_visible_pairs.distance_m", AUTO,
           f"{tag}: closest approach, non-visible pairs [m]", ".1f", source=n),
    ]


NOISE_CASES = (("0", "p002.n0", "0 %", "7"), *[(str(f), f"p002.n{round(f * 100)}", f"{round(f * 100)} %", "7")
                                                for f in NOISE],
               *[(f"{f}-seed{s}", f"p002.n{round(f * 100)}s{s}", f"{round(f * 100)} %", str(s))
                 for f in (0.2, 0.3) for s in SEEDS])
CLAIMS += [c for case, tag, _, _ in NOISE_CASES for c in _case_claims(case, tag)
           if not (c.id.endswith("-dv") and tag != "p002.n0" and case in {str(f) for f in NOISE})]


def _dv_id(case: str, tag: str) -> str:
    """The total-dV claim of a case (the Results table's row 13 already holds the sweep's)."""
    return f"{tag}-dv" if tag == "p002.n0" or "seed" in case else f"p002.noise{tag.removeprefix('p002.n')}-dv"


def _noise_row(case: str, tag: str, label: str, seed: str | None) -> Row:
    lead = (label,) if seed is None else (label, seed)
    return Row((*lead, "{" + _dv_id(case, tag) + "}", f"{{{tag}-last-hour}}",
                *((f"{{{tag}-wc-pct}} %", f"{{{tag}-orbit-wc-pct}} %") if seed is None
                  else (f"{{{tag}-wc-pct}} % / {{{tag}-orbit-wc-pct}} %", f"{{{tag}-split}}")),
                f"{{{tag}-comp-end}} ({{{tag}-comp-max}})", f"{{{tag}-ca-vis}} / {{{tag}-ca-hid}}"))


TABLES += [
    Table("paper002-noise", DOC, ("noise", "total dV [m/s]", "dV in the last hour [m/s]", "weakly connected (per step)",
                                  "weakly connected (orbit union, after the first orbit)",
                                  "components at the end (max)", "closest approach visible / non-visible [m]"),
          tuple(_noise_row(c, t, lab, None) for c, t, lab, _ in NOISE_CASES[:5]), measured=tuple(range(1, 7)),
          align=("---", "---:", "---:", "---:", "---:", "---:", "---:")),
    Table("paper002-noise-seeds", DOC, ("noise", "seed", "total dV [m/s]", "dV in the last hour [m/s]",
                                        "weakly connected per step / orbit union", "orbit-union graph split at the end",
                                        "components at the end (max)", "closest approach visible / non-visible [m]"),
          tuple(_noise_row(c, t, lab, sd) for c, t, lab, sd in sorted(NOISE_CASES[2:3] + NOISE_CASES[5:]
                                                                        + NOISE_CASES[3:4],
                                                                        key=lambda x: (x[2], int(x[3])))),
          measured=tuple(range(2, 8)), align=("---", "---", "---:", "---:", "---:", "---", "---:", "---:")),
]
_SHOWN = {k for t in TABLES for k in t.placeholders()}
CLAIMS = [c for c in CLAIMS if c.id in _SHOWN or not c.id.startswith("p002.n")]  # a run's unshown columns


# --- "How dV depends on the initial dispersion" and the other random draws: 8 more 24 h runs -------
SIGMAS = ("[20, 40, 15, 15, 15, 15]", "[10, 40, 30, 30, 30, 30]", "[20, 40, 30, 30, 30, 30]",
          "[40, 40, 30, 30, 30, 30]", "[20, 40, 60, 60, 60, 60]", "[80, 40, 30, 30, 30, 30]")
OURS = "[20, 40, 30, 30, 30, 30]"
DRAWS = (7, 1, 2, 3)


def _sigma_key(sigma: str) -> str:
    return "p002.s20" if sigma == OURS else "p002.disp-" + "-".join(x.strip() for x in sigma.strip("[]").split(","))


def _init_spread(sets: tuple[str, ...] = (), seed: int | None = None) -> dict[str, Any]:
    """The initial a*da spread (max - min over the spacecraft) of a scenario's draw: no run."""
    from swarmhil.claims.runs import scenario

    sc = scenario("sabatini-20", sets, seed)
    return {"x.init_da_spread_m": float(sc.roe_m[:, 0].max() - sc.roe_m[:, 0].min())}


def _disp_sets(sigma: str) -> tuple[str, ...]:
    return () if sigma == OURS else (f"dispersion.sigma_roe_m={sigma.replace(' ', '')}",)


SOURCES += [
    *[Source(_sigma_key(sg), "all", (lambda st: lambda get: sabatini_metrics("sabatini-20", st))(_disp_sets(sg)),
             f"sabatini-20 --set dispersion.sigma_roe_m={sg.replace(' ', '')}") for sg in SIGMAS if sg != OURS],
    *[Source(f"p002.init-{_sigma_key(sg)}", "quick", (lambda st: lambda get: _init_spread(st))(_disp_sets(sg)),
             f"the initial draw of sabatini-20 with sigma {sg} (no run)") for sg in SIGMAS],
    *[Source(f"p002.draw-{s}", "all", (lambda sd: lambda get: sabatini_metrics("sabatini-20", (), sd))(s),
             f"sabatini-20 --seed {s}") for s in DRAWS if s != 7],
]


def _run_claims(src: str, tag: str, cols: tuple[str, ...]) -> list[Claim]:
    """The columns `cols` of one ideal-sensing run (source `src`), as claims `tag-<col>`."""
    spec = {
        "dv": ("control.delta_v_total_mps", AUTO, ".2f", 1.0), "t95": ("control.t_95pct_delta_v_s", AUTO, ".1f", H),
        "wc": ("connectivity.weakly_connected_fraction", AUTO, ".1f", PCT),
        "owc": ("connectivity.orbit_union_weakly_connected_fraction", AUTO, ".1f", PCT),
        "cend": ("connectivity.components_end", Tol(), "d", 1.0), "cmax": ("connectivity.max_components", Tol(), "d", 1.0),
        "split-h": ("connectivity.first_split_t_s", AUTO, ".2f", H),
        "at": ("closest_visible_steady.along_track_m.min", AUTO, ".0f", 1.0),
        "rd": ("closest_visible_steady.radial_m.min", AUTO, ".1f", 1.0),
        "ct": ("closest_visible_steady.cross_track_m.min", AUTO, ".1f", 1.0),
        "par": ("closest_visible_steady.parallelism.fraction_ge_threshold", AUTO, ".1f", PCT),
        "vis": ("closest_approach.visible_pairs.distance_m", AUTO, ".1f", 1.0),
        "hid": ("closest_approach.non_visible_pairs.distance_m", AUTO, ".1f", 1.0),
    }
    return [_c(f"{tag}-{col}", spec[col][0], spec[col][1], f"{tag}: {spec[col][0]}", spec[col][2], spec[col][3],
               source=src) for col in cols]


_DISP_COLS = ("dv", "t95", "wc", "owc", "cend", "cmax", "at", "rd", "ct", "vis", "hid")
_DRAW_COLS = ("dv", "wc", "owc", "cend", "cmax", "split-h", "rd", "ct", "par", "vis", "hid")


def _dtag(sigma: str) -> str:
    return "p002.d" + "-".join(x.strip() for x in sigma.strip("[]").split(","))


CLAIMS += [c for sg in SIGMAS for c in _run_claims(_sigma_key(sg), _dtag(sg), _DISP_COLS)]
CLAIMS += [_c(f"{_dtag(sg)}-init", "x.init_da_spread_m", AUTO, f"initial a*da spread, sigma {sg} [m]", ".0f",
              source=f"p002.init-{_sigma_key(sg)}") for sg in SIGMAS]
CLAIMS += [c for s in DRAWS for c in _run_claims("p002.s20" if s == 7 else f"p002.draw-{s}", f"p002.r{s}", _DRAW_COLS)]


def _disp_row(sigma: str) -> Row:
    t, b = _dtag(sigma), ("**" if sigma == OURS else "")
    return Row(((f"**{sigma}** (ours)" if sigma == OURS else sigma), f"{{{t}-init}} m", f"{b}{{{t}-dv}}{b}",
                f"{{{t}-t95}} h", f"{{{t}-wc}} % / {{{t}-owc}} %",
                f"{{{t}-cend}} ({{{t}-cmax}})", f"{{{t}-at}} / {{{t}-rd}} / {{{t}-ct}}", f"{{{t}-vis}} / {{{t}-hid}}"))


def _draw_row(seed: int) -> Row:
    t = f"p002.r{seed}"
    return Row((f"{seed} (ours)" if seed == 7 else str(seed), f"{{{t}-dv}}", f"{{{t}-wc}} % / {{{t}-owc}} %",
                f"{{{t}-cend}} ({{{t}-cmax}}), {{{t}-split-h}} h", f"{{{t}-rd}} / {{{t}-ct}}, {{{t}-par}} %",
                f"{{{t}-vis}} / {{{t}-hid}}"))


TABLES += [
    Table("paper002-dispersion", DOC, (
        "sigma [m]", "initial a*da spread", "total dV [m/s]", "95 % of dV by", "weakly connected per step / orbit union",
        "components at the end (max)", "steady-state min along-track / radial / cross-track [m]",
        "closest approach visible / non-visible [m]"), tuple(_disp_row(sg) for sg in SIGMAS), measured=tuple(range(1, 8)),
        align=("---", "---:", "---:", "---:", "---:", "---:", "---", "---:")),
    Table("paper002-draws", DOC, (
        "seed", "total dV [m/s]", "weakly connected per step / orbit union", "components at the end (max), first split",
        "steady-state min radial / cross-track [m], parallelism >= 0.8", "closest approach visible / non-visible [m]"),
        tuple(_draw_row(s) for s in DRAWS), measured=tuple(range(1, 6)),
        align=("---", "---:", "---:", "---", "---", "---:")),
]
