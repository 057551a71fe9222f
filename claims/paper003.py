"""Paper 003 (docs/paper003.md "Paper's numbers vs measured"): the room's 300 s closed loop
(`tests/missions/test_p003_closed_loop.py` `run_closed_loop`, `summary`, `table4`) for the literal
weights and the fast-CT variant, each with the sum or the "ct" saturation. One source per variant
(tier `all`)."""
from __future__ import annotations

from typing import Any, Callable

from claims.missions import mission_test_module
from claims.model import Claim, Row, Source, Table, Tol

DOC = "docs/paper003.md"
MODULE = "test_p003_closed_loop"
AUTO = Tol(auto=True)  # max(3 x cross-kernel spread, half the last printed digit): claims/model.py resolve_tol
VARIANTS = ("literal", "literal-ct-sat", "fast-ct", "fast-ct-ct-sat")  # the columns, as the module's __main__ names them


def _kwargs(m: Any, variant: str) -> dict[str, Any]:
    fast = dict(m.VARIANT_FAST_CT)
    return {"literal": {}, "literal-ct-sat": {"game": {"saturate": "ct"}}, "fast-ct": {"game": fast},
            "fast-ct-ct-sat": {"game": {**fast, "saturate": "ct"}}}[variant]


def _run(variant: str) -> Callable[[Any], dict[str, Any]]:
    def run(_get: Any) -> dict[str, Any]:
        m = mission_test_module(MODULE)
        r = m.run_closed_loop(**_kwargs(m, variant))
        return {k: (float(v) if not isinstance(v, bool) else v) for k, v in {**m.summary(r), **m.table4(r)}.items()}
    return run


SOURCES = [Source(f"p003.{v}", "all", _run(v), f"python tests/missions/test_p003_closed_loop.py {v} (300 s)")
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
