"""Paper 001 (docs/paper001.md "The claims table, checked on the stack"): the full tersoff-6 run
in-process and its report's metrics (tier `study`, ~1 min of CPU), beside the room's closed loop
(`tests/missions/test_p001_closed_loop.py` `simulate` + `summary`) for seed 1 at 1 s steps to
32,000 s (`study`) and at 5 s steps (`all`). CI makes each of these runs in a test, which checks
its claims from it (`checked_by`).

The release study ("Paper vs measured": every release of every reading, 30 runs) is
claims/paper001_study.py, built on the sources here (registered).
"""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping

import numpy as np

from swarmhil.claims.missions import mission_test_module
from swarmhil.claims.model import Claim, Row, Source, Table, Tol

DOC = "docs/paper001.md"
MODULE = "test_p001_closed_loop"
AUTO = Tol(auto=True)  # max(3 x cross-kernel spread, half the last printed digit): claims/model.py resolve_tol
DURATION_S = 32000.0
U_MAX = 5e-3  # m/s^2, LatticeParams' default


def run_summary(m: Any, run: Any) -> dict[str, Any]:
    """The room's `summary` of one run plus what the verdict table reads from the commands: how
    long the agents saturated from t = 0 stay saturated, and the Δv of the first 200 s."""
    s = dict(m.summary(run))
    a = np.linalg.norm(run.acc_mps2, axis=2)  # (steps, N)
    sat = a >= U_MAX * (1 - 1e-9)
    lead = np.argmin(np.vstack([sat, np.zeros((1, sat.shape[1]), bool)]), axis=0)  # leading saturated steps
    s["sat_start_n"] = int(sat[0].sum())
    s["sat_start_max_s"] = float(lead.max() * run.dt_s)
    dv200 = a[: int(round(200.0 / run.dt_s))].sum(axis=0) * run.dt_s
    s["dv_200s_mps"] = [float(dv200.min()), float(dv200.max())]
    s["t_form_s"] = None if math.isnan(s["t_form_s"]) else float(s["t_form_s"])
    for k in ("t_middle_s", "t_inner_s"):
        s[k] = [None if math.isnan(x) else float(x) for x in s[k]]
    s["hexagon"], s["ring"] = bool(s["hexagon"]), bool(s["ring"])
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.items()}


def _key(reading: str, release: str | int) -> str:
    return f"p001.{reading}-{release}"


def _run(reading: str, release: str | int) -> Callable[[Any], dict[str, Any]]:
    def run(_get: Any) -> dict[str, Any]:
        m = mission_test_module(MODULE)
        r = m.simulate(m.sphere_directions(None if release == "oct" else int(release)), DURATION_S, dt_s=1.0,
                       params=m.READINGS[reading], record_every=10)
        return run_summary(m, r)
    return run


def from_run(run: Any) -> dict[str, Any]:
    """A test's run (the same `simulate` call) as this module's source result."""
    return run_summary(mission_test_module(MODULE), run)


TEST = "tests/missions/test_p001_closed_loop.py"
CI_CASES = {("paper", 1), ("paper", "oct"), ("literal", 2)}  # the system test's CI_CASES: checked from its runs


def release_source(reading: str, release: str | int) -> Source:
    """One release of one reading at 1 s steps to 32,000 s (tier `study`)."""
    return Source(_key(reading, release), "study", _run(reading, release),
                  f"python {TEST} {release} 32000 (1 s steps, reading {reading})",
                  **({"checked_by": f"{TEST}::test_release_to_structure_at_1s_steps", "from_run": from_run}
                     if (reading, release) in CI_CASES else {}))



def _none_dash(v: Any) -> Any:
    return "—" if v is None else v


RUN_FIELDS: tuple[tuple[str, Callable[[Mapping[str, Any]], Any], str, Tol], ...] = (
    ("structure", lambda s: s["structure"], "", Tol()),
    ("side-min", lambda s: s["sides_m"][0], ".2f", AUTO), ("side-max", lambda s: s["sides_m"][1], ".2f", AUTO),
    *[(f"centre-{ax}", (lambda i: lambda s: s["centre_m"][i])(i), ".2f", AUTO) for i, ax in enumerate("xyz")],
    ("phase", lambda s: s["phase_deg"], ".1f", AUTO), ("eq16", lambda s: s["eq16"], ".4f", AUTO),
    ("t-form", lambda s: _none_dash(s["t_form_s"]), ".1f", AUTO),
    ("mid-first", lambda s: min(x for x in s["t_middle_s"] if x is not None), ".0f", AUTO),
    ("mid-last", lambda s: max(x for x in s["t_middle_s"] if x is not None), ".0f", AUTO),
    ("v-max", lambda s: s["v_max_mps"], ".3f", AUTO), ("d-min", lambda s: s["d_min_m"], ".2f", AUTO),
    ("dv-min", lambda s: min(s["dv_mps"]), ".2f", AUTO), ("dv-max", lambda s: max(s["dv_mps"]), ".2f", AUTO),
)


def release_claims(reading: str, release: str | int) -> list[Claim]:
    """The columns of one release's row (docs/paper001.md's per-reading tables)."""
    k = _key(reading, release)
    return [Claim(f"{k}.{name}", k, fn, tol, f"{reading} reading, release {release}: {name}", fmt or ".3g")
            for name, fn, fmt, tol in RUN_FIELDS]


SOURCES = [release_source("paper", 1)]
CLAIMS = release_claims("paper", 1)
TABLES: list[Table] = []

# --- "The claims table, checked on the stack": full tersoff-6 in-process, the report's metrics -----
STACK_S = 40000.0


def stack_metrics(truth: Any) -> dict[str, Any]:
    """`swarmhil report`'s `p001-formation` metrics (missions/p001_lattice/report.py `formation_metrics`)
    of a tersoff-6 truth, plus who saturated when."""
    from swarmhil.missions.p001_lattice.report import formation_metrics, lattice_params

    from swarmhil.claims.runs import scenario

    sc = scenario("tersoff-6")
    alive = truth.alive.all(axis=1)
    t, pos, vel, acc = truth.t_s[alive], truth.position_m[alive], truth.velocity_mps[alive], truth.accel_mps2[alive]
    met, series = formation_metrics(t, pos, vel, acc, list(truth.ids), lattice_params({"controller": {
        "params": sc.controller_params}}), float(sc.max_accel_mps2))
    sat = series["thrust"] >= met["thrust"]["limit_mps2"] * (1 - 1e-6)
    k, i = np.nonzero(sat)
    met["x_dv_mps"] = [float(x) for x in truth.delta_v_mps[-1]]
    met["x_sat_release"] = int(sat[0].sum())
    met["x_sat_later"] = [f"{truth.ids[j]} at {t[s]:,.0f} s".replace(",", " ") for s, j in zip(k, i) if s > 0]
    return met


def _stack_run(_get: Any) -> dict[str, Any]:
    from swarmhil.claims.runs import run_truth, scenario

    return stack_metrics(run_truth(scenario("tersoff-6", duration_s=STACK_S)))


def _run_5s(_get: Any) -> dict[str, Any]:
    m = mission_test_module(MODULE)
    return run_summary(m, m.simulate(m.sphere_directions(1), DURATION_S, dt_s=5.0, record_every=2))


STACK_TEST = "tests/missions/test_p001_stack.py::test_full_run_forms_the_hexagon_of_side_10_m"
SOURCES += [
    Source("p001.stack", "study", _stack_run, "swarmhil run deploy/scenarios/tersoff-6.toml --in-process (40,000 s) "
           "and its report's p001-formation metrics", checked_by=STACK_TEST, from_run=stack_metrics),
    Source("p001.paper-1-5s", "all", _run_5s, f"the room's loop, seed 1, 5 s steps to 32,000 s ({TEST})",
           checked_by=f"{TEST}::test_paper_reading_seed1_forms_the_hexagon_centred_on_the_dock_vertex",
           from_run=from_run),
]


def _inner(s: Mapping[str, Any]) -> list[tuple[float, str]]:
    return sorted((float(v), k) for k, v in s["gathering"]["enter_inner_s"].items() if v is not None)


def _sc(id_: str, fn: Callable[[Mapping[str, Any]], Any], what: str, fmt: str = ".3g", tol: Tol = AUTO,
        residual: bool = False) -> Claim:
    return Claim(f"p001.stack.{id_}", "p001.stack", fn, tol, f"tersoff-6 on the stack: {what}", fmt, residual=residual)


CLAIMS += [
    _sc("mid-first", lambda s: s["gathering"]["enter_middle_span_s"][0], "first r_middle entry [s]", ",.0f"),
    _sc("mid-last", lambda s: s["gathering"]["enter_middle_span_s"][1], "last r_middle entry [s]", ",.0f"),
    _sc("inner-n", lambda s: len(_inner(s)), "agents inside the 15 m ball by the end", "d", Tol()),
    _sc("inner-first", lambda s: _inner(s)[0][0], "first entry into the 15 m ball [s]", ",.0f"),
    _sc("inner-5th", lambda s: _inner(s)[4][0], "fifth entry [s]", ",.0f"),
    _sc("inner-last", lambda s: _inner(s)[-1][0], "last entry [s]", ",.0f"),
    _sc("inner-last-id", lambda s: _inner(s)[-1][1], "who enters last", "", Tol()),
    _sc("v-max", lambda s: s["speed"]["max_mps"], "largest speed [m/s]", ".3f"),
    _sc("u-max", lambda s: s["thrust"]["max_mps2"], "largest |u| [m/s^2]", ".1e"),
    _sc("sat-steps", lambda s: s["thrust"]["saturated_steps"], "saturated agent-steps", "d", Tol()),
    _sc("sat-release", lambda s: s["x_sat_release"], "of them at release", "d", Tol()),
    _sc("sat-later", lambda s: "; ".join(s["x_sat_later"]) or "none", "the later ones", "", Tol()),
    _sc("d-min", lambda s: s["closest_approach"]["distance_m"], "closest approach [m]", ".2f"),
    _sc("d-pair", lambda s: "–".join(s["closest_approach"]["pair"]), "its pair", "", Tol()),
    _sc("d-t", lambda s: s["closest_approach"]["t_s"], "its time [s]", ",.0f"),
    _sc("structure", lambda s: s["final"]["structure"], "final structure", "", Tol()),
    _sc("hexagon", lambda s: "yes" if s["final"]["is_hexagon"] else "no", "the hexagon test", "", Tol()),
    _sc("side", lambda s: (s["final"]["side_min_m"] + s["final"]["side_max_m"]) / 2, "mean of the extreme sides [m]",
        ".2f"),
    # residuals: round-off around the plane x = 0 (|x| 3.4e-9 m on both kernel sets, 1e-17 apart): any
    # value below 1e-8 m; the centre's x (3.9e-10 m) within half the printed digit, 0.005 m
    _sc("max-x", lambda s: s["final"]["max_abs_x_m"], "largest |x| at the end [m]", ".0e", Tol(abs=1e-8),
        residual=True),
    *[_sc(f"centre-{ax}", (lambda i: lambda s: s["final"]["centre_m"][i])(i), f"centre {ax} [m]", ".2f",
          residual=ax == "x") for i, ax in enumerate("xyz")],
    _sc("phase", lambda s: s["final"]["phase_deg"], "phase [deg]", ".1f"),
    _sc("formed", lambda s: _none_dash(s["formed_s"]), "formed at [s]", ",.0f"),
    _sc("eq16", lambda s: s["eq16"]["end"], "eq. 16 at the end", ".4f"),
    _sc("eq16-min", lambda s: s["eq16"]["min"], "eq. 16 minimum", ".4f"),
    _sc("eq16-min-t", lambda s: s["eq16"]["t_min_s"], "its time [s]", ",.0f"),
    _sc("dv-min", lambda s: min(s["x_dv_mps"]), "smallest Δv of an agent [m/s]", ".2f"),
    _sc("dv-max", lambda s: max(s["x_dv_mps"]), "largest Δv of an agent [m/s]", ".2f"),
    Claim("p001.paper-1-5s.t-form", "p001.paper-1-5s", lambda s: _none_dash(s["t_form_s"]), AUTO,
          "the room's loop, seed 1, 5 s steps: formed at [s]", ",.0f"),
]

S, R = "{p001.stack.", "{p001.paper-1."
STACK_ROWS = (
    Row(("edge of the artificial layer", "~16,880 s", "`gathering.enter_middle_span_s`", f"{S}mid-first}}–{S}mid-last}} s",
         f"{R}mid-first:,.0f}}–{R}mid-last:,.0f}} s")),
    Row(("inside the 15 m ball", "—", "`gathering.enter_inner_s`",
         f"{S}inner-first}}–{S}inner-5th}} s for five agents, {S}inner-last}} s for {S}inner-last-id}} "
         f"({S}inner-n}} of six inside)", "—"), params=("15",)),
    Row(("speeds below 0.18 m/s", "< 0.18 m/s", "`speed.max_mps`", f"{S}v-max}} m/s", f"{R}v-max}} m/s (1 s steps)"),
        params=("1",)),
    Row(("thrust within u_max", "≤ 5e-3 m/s²", "`thrust.max_mps2`",
         f"{S}u-max}} m/s² ({S}sat-steps}} saturated agent-steps: {S}sat-release}} at release; {S}sat-later}})",
         "≤ u_max")),
    Row(("no collision", "none", "`closest_approach.distance_m`", f"{S}d-min}} m ({S}d-pair}}, {S}d-t}} s)",
         f"{R}d-min}} m")),
    Row(("hexagon of side l in the yz-plane", "yes", "`final.structure`, `final.is_hexagon`, `final.max_abs_x_m`",
         f"{S}structure}}, {S}hexagon}}, sides {S}side}} m, \\|x\\| ≤ {S}max-x}} m",
         f"{R}structure}}, {R}side-min}}–{R}side-max}} m")),
    Row(("centred at the origin, phase 30°", "yes", "`final.centre_m`, `final.phase_deg`",
         f"({S}centre-x}}, {S}centre-y}}, {S}centre-z}}) m, {S}phase}}°",
         f"({R}centre-x}}, {R}centre-y}}, {R}centre-z}}) m, {R}phase}}°")),
    Row(("time to form", "< 25,000 s", "`formed_s`", f"{S}formed}} s",
         f"{R}t-form:,.0f}} s (1 s), {{p001.paper-1-5s.t-form}} s (5 s)"), params=("1", "5")),
    Row(("eq. 16", "0.0125", "`eq16.end`", f"{S}eq16}} (min {S}eq16-min}} at {S}eq16-min-t}} s)", f"{R}eq16}}")),
    Row(("Δv per agent", "not given", "`delta_v_mps` (summary.json)", f"{S}dv-min}}–{S}dv-max}} m/s (40,000 s)",
         f"{R}dv-min}}–{R}dv-max}} m/s (1 s steps, 32,000 s)"), params=("40,000", "1", "32,000")),
)
TABLES.append(Table("paper001-stack", DOC, ("claim (paper §III)", "paper", "report key", "stack, seed 1",
                                            "room's loop, seed 1 (table above)"), STACK_ROWS, measured=(3, 4)))
