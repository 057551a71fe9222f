"""Paper 003 (docs/paper003.md): the room's 300 s closed loop (`tests/missions/test_p003_closed_loop.py`
`run_closed_loop`, `summary`, `table4`).

"Paper's numbers vs measured": the literal weights and the fast-CT variant, each with the sum or the
"ct" saturation (16-20 s of CPU each). "Target tracking": leader-only runs (5-6 s each) from the
Table 3 initialisations, escape forces, LEO and GEO. Runs a CI test already makes are checked by
that test from its run (`checked_by`, claims/check.py): fast-CT by the default test, the literal
weights, the four Table 3 groups and the LEO 0 / 10 N runs by the system tests; the other runs are
tier `all`.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from swarmhil.claims.missions import mission_test_module
from swarmhil.claims.model import Claim, Row, Source, Table, Tol

DOC = "docs/paper003.md"
MODULE = "test_p003_closed_loop"
TEST = "tests/missions/test_p003_closed_loop.py"
AUTO = Tol(auto=True)  # max(3 x cross-kernel spread, half the last printed digit): claims/model.py resolve_tol
VARIANTS = ("literal", "literal-ct-sat", "fast-ct", "fast-ct-ct-sat")  # the columns, as the module's __main__ names them
CHECKED_BY = {"literal": f"{TEST}::test_literal_weights_keep_safety_and_show_the_slow_mode",
              "fast-ct": f"{TEST}::test_fast_ct_variant_meets_the_papers_outcomes"}


def _kwargs(m: Any, variant: str) -> dict[str, Any]:
    fast = dict(m.VARIANT_FAST_CT)
    return {"literal": {}, "literal-ct-sat": {"game": {"saturate": "ct"}}, "fast-ct": {"game": fast},
            "fast-ct-ct-sat": {"game": {**fast, "saturate": "ct"}}}[variant]


def variant_result(run: Any) -> dict[str, Any]:
    """A servicer run's numbers: the room's `summary` and `table4`."""
    m = mission_test_module(MODULE)
    return {k: (float(v) if not isinstance(v, bool) else v) for k, v in {**m.summary(run), **m.table4(run)}.items()}


def _run(variant: str) -> Callable[[Any], dict[str, Any]]:
    def run(_get: Any) -> dict[str, Any]:
        m = mission_test_module(MODULE)
        return variant_result(m.run_closed_loop(**_kwargs(m, variant)))
    return run


def _checked(key: str, table: dict[str, str], conv: Callable[[Any], dict[str, Any]]) -> dict[str, Any]:
    return {"checked_by": table[key], "from_run": conv} if key in table else {}


SOURCES = [Source(f"p003.{v}", "all", _run(v), f"python {TEST} {v} (300 s)", **_checked(v, CHECKED_BY, variant_result))
           for v in VARIANTS]

# (field, claim suffix, format, scale)
FIELDS: tuple[tuple[str, str, str, float], ...] = (
    ("min_funnel_margin_ratio", "tt-ratio", ".2f", 1.0), ("tt_err_300s_m", "tt-300", ".2f", 1.0),
    ("funnel_300s_m", "funnel-300", ".2f", 1.0), ("leader_peak_n", "leader-peak", ".1f", 1.0),
    ("ct_pos_300s_m", "ct-pos", ".3g", 1.0), ("ct_vel_300s_mps", "ct-vel", ".2g", 1.0),
    ("min_pair_m", "min-pair", ".1f", 1.0), ("min_clearance_m", "min-clear", ".1f", 1.0),
    ("sat_peak_n", "sat-peak", ".1f", 1.0), ("sat_saturated_frac", "sat-frac", ".1f", 100.0),
    ("ATFC_mps", "atfc", ".1f", 1.0), ("AMD_sat_m", "amd-sat", ".1f", 1.0),
    *[(f"AMD_obs_{i}_m", f"amd-obs{i}", ".0f", 1.0) for i in range(1, 7)],
)


def _claims(variant: str) -> list[Claim]:
    src = f"p003.{variant}"
    out = [Claim(f"{src}.tt-inside", src, lambda s: "yes" if s["tt_inside_funnel"] else "no", Tol(),
                 f"{variant}: TT error inside the funnel at all t")]
    for field, suffix, fmt, scale in FIELDS:
        out.append(Claim(f"{src}.{suffix}", src, (lambda f, k: lambda s: float(s[f]) * k)(field, scale), AUTO,
                         f"{variant}: {field}", fmt))
    return out


CLAIMS = [c for v in VARIANTS for c in _claims(v)]


def _row(claim: str, paper: str, template: str) -> Row:
    """One row: the same template for every variant, `{c}` standing for `p003.<variant>.`."""
    return Row((claim, paper, *[template.replace("{c}", "{p003." + v + ".") for v in VARIANTS]))


HEADER = ("claim (§5)", "paper", "literal", "literal, \"ct\" sat.", "fast-CT", "fast-CT, \"ct\" sat.")
ROWS: tuple[tuple[str, str, str], ...] = (  # claim, the paper's figure, what each variant's column shows
    ("TT error inside ±tan(k1 π/2) at all t", "yes", "{c}tt-inside} (worst ‖q̃‖∞/bound {c}tt-ratio})"),
    ("TT error at 300 s", "\"[−1, 1] m\"", "{c}tt-300} m"), ("funnel half-width at 300 s", "(±1 m claimed)", "{c}funnel-300} m"),
    ("peak leader thrust", "≤ 180 N", "{c}leader-peak} N"), ("max ‖q̃_Li‖ at 300 s", "< 5 m", "{c}ct-pos} m"),
    ("max ‖q̃̇_Li‖ at 300 s", "< 0.5 m/s", "{c}ct-vel} m/s"),
    ("min servicer–servicer distance (centres)", "> 5 m (Fig. 11)", "{c}min-pair} m"),
    ("min clearance to a sphere surface", "CCS = 0 (Fig. 12)", "{c}min-clear} m"),
    ("peak servicer thrust", "≤ 20 N", "{c}sat-peak} N"),
    ("fraction of servicer-steps saturated", "~0–80 s (Fig. 16)", "{c}sat-frac} %"),
    ("ATFC", "75.12 m/s", "{c}atfc} m/s"), ("AMD_sat", "83.3 m", "{c}amd-sat} m"),
    ("AMD_obs, SSat 1–6", "88.21, 88.49, 85.75, 88.46, 90.81, … m",
     ", ".join("{c}amd-obs" + str(i) + "}" for i in range(1, 7)) + " m"),
)
TABLES = [Table("paper003-numbers", DOC, HEADER, measured=(2, 3, 4, 5), rows=tuple(_row(*r) for r in ROWS))]


# --- "Target tracking": leader-only runs ----------------------------------------------------------
GEO_ALT_M = 35786e3
TT_RUNS: tuple[tuple[str, str, dict[str, Any]], ...] = (  # claim tag, doc label, run_closed_loop keywords
    ("g1", "Table 3 group 1: q_TL(0) = (900, 500, 500) m, (5, 5, 5) m/s", {}),
    ("g2", "group 2: (600, 200, 200), (2, 2, 2)", {"group": 2}),
    ("g3", "group 3: (200, −200, −200), (−2, −2, −2) (signs chosen)", {"group": 3}),
    ("g4", "group 4: (−100, −500, −500), (−5, −5, −5) (signs chosen)", {"group": 4}),
    ("leo0", "LEO, escape 0 N", {"escape_n": 0.0}),
    ("leo1", "LEO, escape 1 N/axis", {"escape_n": 1.0}),
    ("leo3", "LEO, escape 3 N/axis", {}),  # = group 1: the same run
    ("leo10", "LEO, escape 10 N/axis", {"escape_n": 10.0}),
    ("geo0", "GEO, escape 0 N", {"escape_n": 0.0, "altitude_m": GEO_ALT_M}),
    ("geo3", "GEO, escape 3 N/axis", {"altitude_m": GEO_ALT_M}),
)
TT_CHECKED_BY = {"g1": f"{TEST}::test_table3_initialisations_stay_inside_the_funnel",
                 "g2": f"{TEST}::test_table3_initialisations_stay_inside_the_funnel",
                 "g3": f"{TEST}::test_table3_initialisations_stay_inside_the_funnel",
                 "g4": f"{TEST}::test_table3_initialisations_stay_inside_the_funnel",
                 "leo0": f"{TEST}::test_tt_bias_grows_with_the_escape_force",
                 "leo10": f"{TEST}::test_tt_bias_grows_with_the_escape_force"}
TT_SAME = {"leo3": "g1"}  # the same keywords: one run, two rows


def tt_result(run: Any) -> dict[str, Any]:
    """A leader-only run's row (`tt_report`'s numbers): TT error at the end, worst ‖q̃‖∞ / funnel,
    first time below 10 m, peak leader thrust."""
    err = np.abs(run.tt_err_m)
    below = np.nonzero(err.max(axis=1) < 10.0)[0]
    return {"tt_end_m": float(err[-1].max()), "ratio": float((err[1:].max(axis=1) / run.funnel_m[1:]).max()),
            "first_below_10m_s": float(run.t_s[below[0]]) if below.size else float("nan"),
            "peak_n": float(run.leader_thrust_n.max())}


def _tt_run(kw: dict[str, Any]) -> Callable[[Any], dict[str, Any]]:
    def run(_get: Any) -> dict[str, Any]:
        m = mission_test_module(MODULE)
        args = {k: v for k, v in kw.items() if k != "group"}
        if "group" in kw:
            args["q_tl0_m"], args["v_tl0_mps"] = m.TABLE3_GROUPS[kw["group"]]
        return tt_result(m.run_closed_loop(with_servicers=False, **args))
    return run


SOURCES += [Source(f"p003.tt-{tag}", "all", _tt_run(kw), f"leader-only run of `python {TEST} tt`: {label}",
                   **_checked(tag, TT_CHECKED_BY, tt_result))
            for tag, label, kw in TT_RUNS if tag not in TT_SAME]
TT_FIELDS = (("tt-end", "tt_end_m", ".2f"), ("ratio", "ratio", ".3f"), ("first10", "first_below_10m_s", ".1f"),
             ("peak", "peak_n", ".1f"))
CLAIMS += [Claim(f"p003.tt-{tag}.{suffix}", f"p003.tt-{TT_SAME.get(tag, tag)}",
                 (lambda k: lambda s: float(s[k]))(key), AUTO, f"leader only, {label}: {key}", fmt)
           for tag, label, _ in TT_RUNS if tag not in TT_SAME for suffix, key, fmt in TT_FIELDS]


def _tt_row(tag: str, label: str) -> Row:
    p = "{p003.tt-" + TT_SAME.get(tag, tag) + "."
    return Row((label, f"{p}tt-end}} m", p + "ratio}", f"{p}first10}} s", f"{p}peak}} N"))


TABLES.append(Table("paper003-tt", DOC, ("run", "TT error at 300 s", "worst ‖q̃‖∞ / bound", "first < 10 m",
                                          "peak ‖u_L‖"), tuple(_tt_row(t, lab) for t, lab, _ in TT_RUNS),
                    measured=(1, 2, 3, 4)))
