"""Paper 001's release study (docs/paper001.md "Paper vs measured"): the room's closed loop at 1 s
steps to 32,000 s for every release of every reading (30 runs, tier `study`: 20-80 s of CPU each,
~7-25 min of wall each on the shared machine at a load average of 10-45), the per-reading tables
and the verdict table made from them; the relaxed TB hexagon's eq. 16 (`quick`, no run).

Registered 2026-12-03: the 30 releases recorded with the default kernels (30-50 s of CPU each);
under the other kernel set only paper 1 and oct so far (identical). To complete: `swarmhil claims
--study --only p001.paper --record` (and centred, literal, ae) under OPENBLAS_CORETYPE=Sandybridge
NPY_DISABLE_CPU_FEATURES=X86_V3.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import numpy as np

from swarmhil.claims.model import Claim, Row, Source, Table, Tol, Values
from swarmhil.claims.paper001 import AUTO, DOC, U_MAX, _key, release_claims, release_source

PAPER_MIDDLE_S, PAPER_FORM_S, PAPER_V_MPS, PAPER_EQ16 = 16880.0, 25000.0, 0.18, 0.0125
RELEASES: dict[str, tuple[str | int, ...]] = {  # as the doc's tables list them
    "paper": ("oct", *range(10)), "centred": ("oct", *range(10)),
    "literal": ("oct", 1, 2, 3), "ae": ("oct", 1, 2, 3),
}
REGISTERED = {("paper", 1)}  # claims/paper001.py holds this release's source and claims


def _tb_relaxed(_get: Any) -> dict[str, Any]:
    """The regular hexagon relaxed in the TB field alone (normalised cutoffs): its side and eq. 16
    (tests/missions/test_p001_lattice.py checks the same)."""
    from scipy.optimize import minimize_scalar

    from swarmhil.missions.p001_lattice.contract import hexagon_vertices, mean_relative_error
    from swarmhil.missions.p001_lattice.fsw.tersoff import energy, tersoff_params

    p = tersoff_params("normalised")
    hexa = hexagon_vertices(1.0)
    side = minimize_scalar(lambda s: energy(hexa * s, p), bounds=(0.8, 1.3), method="bounded",
                           options={"xatol": 1e-10}).x
    return {"side_l": float(side), "eq16": float(mean_relative_error(hexa * side * 10.0, 10.0))}


def _study(reading: str) -> Callable[[Callable[[str], dict[str, Any]]], dict[str, Any]]:
    """One reading's releases side by side (derived: no run of its own)."""
    return lambda get: {str(r): get(_key(reading, r)) for r in RELEASES[reading]}


SOURCES = [
    *[release_source(rd, r) for rd, rels in RELEASES.items() for r in rels if (rd, r) not in REGISTERED],
    *[Source(f"p001.{rd}", "study", _study(rd), f"the {rd} reading's {len(rels)} runs above (derived)",
             uses=tuple(_key(rd, r) for r in rels)) for rd, rels in RELEASES.items()],
    Source("p001.tb", "quick", _tb_relaxed, "the regular hexagon relaxed in the TB field (no run)"),
]
CLAIMS = [c for rd, rels in RELEASES.items() for r in rels if (rd, r) not in REGISTERED for c in release_claims(rd, r)]


def _release_row(reading: str, release: str | int) -> Row:
    p = "{" + _key(reading, release) + "."
    return Row((str(release), p + "structure}", f"{p}side-min}}–{p}side-max}}",
                f"({p}centre-x}}, {p}centre-y}}, {p}centre-z}})", p + "phase}", p + "eq16}", p + "t-form}",
                f"{p}mid-first}}–{p}mid-last}}", p + "v-max}", p + "d-min}", f"{p}dv-min}}–{p}dv-max}}"))


RUN_HEADER = ("release", "structure at 32,000 s", "sides m", "centre m", "phase °", "eq. 16", "t_form s",
              "r_middle crossed s", "v_max m/s", "d_min m", "Δv m/s")
TABLES = [Table(f"paper001-{rd}", DOC, RUN_HEADER, tuple(_release_row(rd, r) for r in rels),
                measured=tuple(range(1, 11))) for rd, rels in RELEASES.items()]


# --- the verdict table: aggregates over a reading's runs -------------------------------------------
def _hexes(s: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any]]]:
    return [(r, x) for r, x in s.items() if x["hexagon"]]


def _agg(src: str, id_: str, fn: Callable[[Mapping[str, Any]], Any], what: str, fmt: str = ".3g",
         tol: Tol = AUTO) -> Claim:
    return Claim(f"p001.v.{id_}", src, fn, tol, what, fmt)


def _seeds(s: Mapping[str, Any], want: Callable[[Mapping[str, Any]], bool]) -> tuple[str, ...]:
    return tuple(r for r, x in s.items() if want(x))


def _traps(s: Mapping[str, Any]) -> str:
    """'five-ring + 1 (seed 0); 3-D 3-ring+3 (seeds 5, 8); ...': each trap structure and its releases."""
    by: dict[str, list[str]] = {}
    for r, x in s.items():
        if not x["hexagon"]:
            by.setdefault(x["structure"], []).append(r)
    return "; ".join(f"{k} ({', '.join(v)})" for k, v in by.items())


P, C = "p001.paper", "p001.centred"
ALL_READINGS = tuple(RELEASES)
CLAIMS += [
    _agg(P, "mid-first", lambda s: min(min(y for y in x["t_middle_s"] if y is not None) for x in s.values()),
         "paper reading: first r_middle crossing over the releases [s]", ",.0f"),
    _agg(P, "mid-last", lambda s: max(max(y for y in x["t_middle_s"] if y is not None) for x in s.values()),
         "paper reading: last r_middle crossing over the releases [s]", ",.0f"),
    _agg(P, "sat-none", lambda s: sum(x["sat_start_n"] < 6 for x in s.values()), "paper reading: releases in "
         "which some agent is not saturated at t = 0", "d", Tol()),
    _agg(P, "sat-max-s", lambda s: max(x["sat_start_max_s"] for x in s.values()),
         "paper reading: longest saturation from t = 0 [s]", ".0f"),
    _agg(P, "v-max", lambda s: max(x["v_max_mps"] for x in s.values()), "paper reading: largest speed [m/s]", ".3f"),
    _agg(P, "u-max", lambda s: max(x["u_max_mps2"] for x in s.values()), "paper reading: largest |u| [m/s^2]",
         ".1e"),
    _agg(P, "d-min", lambda s: min(x["d_min_m"] for x in s.values()), "paper reading: closest pair [m]", ".2f"),
    _agg(P, "n-hex", lambda s: len(_hexes(s)), "paper reading: releases that form the hexagon", "d", Tol()),
    _agg(P, "n-rel", lambda s: len(s), "paper reading: releases", "d", Tol()),
    _agg(P, "hex-seeds", lambda s: _seeds(s, lambda x: x["hexagon"]), "paper reading: which", "", Tol()),
    _agg(P, "traps", _traps, "paper reading: the traps and their releases", "", Tol()),
    *[_agg(P, f"hex-centre-{ax}", (lambda i: lambda s: float(np.mean([x["centre_m"][i] for _, x in _hexes(s)])))(i),
           f"paper reading: mean hexagon centre {ax} [m]", ".2f") for i, ax in enumerate("xyz")],
    _agg(C, "off-origin", lambda s: max(float(np.linalg.norm(x["centre_m"])) for _, x in _hexes(s)),
         "centred reading: hexagon centre's largest distance to the origin [m]", ".2f"),
    _agg(C, "phase-min", lambda s: min(x["phase_deg"] for _, x in _hexes(s)), "centred reading: phase min [deg]",
         ".1f"),
    _agg(C, "phase-max", lambda s: max(x["phase_deg"] for _, x in _hexes(s)), "centred reading: phase max [deg]",
         ".1f"),
    _agg(P, "form-min", lambda s: min(x["t_form_s"] for _, x in _hexes(s)), "paper reading: earliest t_form [s]",
         ",.0f"),
    _agg(P, "form-max", lambda s: max(x["t_form_s"] for _, x in _hexes(s)), "paper reading: latest t_form [s]",
         ",.0f"),
    _agg(P, "dv-min", lambda s: min(min(x["dv_mps"]) for x in s.values()), "paper reading: smallest Δv [m/s]",
         ".2f"),
    _agg(P, "dv-max", lambda s: max(max(x["dv_mps"]) for x in s.values()), "paper reading: largest Δv [m/s]",
         ".2f"),
    _agg(P, "dv200-min", lambda s: s["1"]["dv_200s_mps"][0], "paper reading, seed 1: Δv of the first 200 s, "
         "smallest [m/s]", ".2f"),
    _agg(P, "dv200-max", lambda s: s["1"]["dv_200s_mps"][1], "paper reading, seed 1: Δv of the first 200 s, "
         "largest [m/s]", ".2f"),
    _agg(P, "hex-eq16-min", lambda s: min(x["eq16"] for _, x in _hexes(s)), "paper reading: eq. 16 of the "
         "hexagons, smallest", ".4f"),
    _agg(P, "hex-eq16-max", lambda s: max(x["eq16"] for _, x in _hexes(s)), "largest", ".4f"),
    _agg(P, "hex-side", lambda s: float(np.mean([x["sides_m"] for _, x in _hexes(s)])),
         "paper reading: the hexagons' mean side [m]", ".2f"),
    _agg("p001.tb", "tb-eq16", lambda s: s["eq16"], "eq. 16 of the hexagon relaxed in the TB field alone", ".4f"),
]


def _v_middle(v: Values) -> str:
    lo, hi = float(v["p001.v.mid-first"]), float(v["p001.v.mid-last"])
    return "reproduced" if lo <= PAPER_MIDDLE_S * 1.1 and hi >= PAPER_MIDDLE_S * 0.9 else "not reproduced"


def _v_sat(v: Values) -> str:
    return "partly (depends on k_g, direction)" if int(v["p001.v.sat-none"]) > 0 else "reproduced"


def _v_hex(v: Values) -> str:
    n, of = int(v["p001.v.n-hex"]), int(v["p001.v.n-rel"])
    return "reproduced" if n == of else ("partly: a local-minimum lottery" if n else "not reproduced")


def _v_centre(v: Values) -> str:
    off = math.hypot(float(v["p001.v.hex-centre-x"]), float(v["p001.v.hex-centre-y"]), float(v["p001.v.hex-centre-z"]))
    centred = float(v["p001.v.off-origin"]) < 0.1 and abs(float(v["p001.v.phase-min"]) - 30) < 2 \
        and abs(float(v["p001.v.phase-max"]) - 30) < 2
    if off < 0.1:
        return "reproduced"
    return "not with Table 3 as printed; yes with g_free kept in the ball" if centred else "not reproduced"


def _v_eq16(v: Values) -> str:
    lo, hi = float(v["p001.v.hex-eq16-min"]), float(v["p001.v.hex-eq16-max"])
    return "reproduced" if lo <= PAPER_EQ16 * 1.25 and hi >= PAPER_EQ16 / 1.25 else "not (different number; the wells set it)"


VERDICT_ROWS = (
    Row(("gathering timeline: edge of the artificial layer", "\"roughly after 16,880 s\"",
         "r_middle crossed {p001.v.mid-first}–{p001.v.mid-last} s"), _v_middle),
    Row(("thrusters saturated at the start (Fig. 4a)", "yes",
         "only agents whose ballistic speed > 0.1 m/s (k_g = 0.05 s⁻¹): not all six in "
         "{p001.v.sat-none} of {p001.v.n-rel} releases; up to {p001.v.sat-max-s} s"), _v_sat,
        ("0.1", "0.05")),
    Row(("speeds below 0.18 m/s", "< 0.18 m/s", "≤ {p001.v.v-max} m/s in every release"),
        lambda v: "reproduced" if float(v["p001.v.v-max"]) < PAPER_V_MPS else "not reproduced"),
    Row(("thrust within u_max", "≤ 5e-3 m/s²", "≤ {p001.v.u-max} m/s² (norm)"),
        lambda v: "reproduced (by construction)" if float(v["p001.v.u-max"]) <= U_MAX * (1 + 1e-12) else "not reproduced"),
    Row(("no collision", "none", "d_min ≥ {p001.v.d-min} m"),
        lambda v: "reproduced" if float(v["p001.v.d-min"]) > 5.0 else "not reproduced"),
    Row(("hexagon of side l in the yz-plane", "yes, one run",
         "{p001.v.n-hex} of {p001.v.n-rel} releases ({p001.v.hex-seeds}); traps: {p001.v.traps}"), _v_hex),
    Row(("centred at the origin, phase 30°", "yes",
         "paper reading: centred on the dock vertex ({p001.v.hex-centre-x}, {p001.v.hex-centre-y}, "
         "{p001.v.hex-centre-z}) m, phase free; centred reading: origin within {p001.v.off-origin} m, phase "
         "{p001.v.phase-min}–{p001.v.phase-max}°"), _v_centre),
    Row(("time to form", "< 25,000 s", "{p001.v.form-min}–{p001.v.form-max} s"),
        lambda v: "reproduced when it forms" if float(v["p001.v.form-max"]) < PAPER_FORM_S else "not reproduced"),
    Row(("Δv per agent", "not given", "{p001.v.dv-min}–{p001.v.dv-max} m/s ({p001.v.dv200-min}–{p001.v.dv200-max} "
         "m/s of it in the first 200 s, seed 1)"), lambda v: "—", ("200", "1")),
    Row(("eq. 16", "0.0125", "{p001.v.hex-eq16-min}–{p001.v.hex-eq16-max} (sides {p001.v.hex-side} m) for every "
         "hexagon; {p001.v.tb-eq16} for TB alone"), _v_eq16),
)
TABLES.insert(0, Table("paper001-verdicts", DOC, ("claim (paper §III)", "paper", "measured (paper reading)", "verdict"),
                       VERDICT_ROWS, measured=(2,), verdict_col=3))

