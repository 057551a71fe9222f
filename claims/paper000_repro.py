"""Paper 000 over seeds on the stack (docs/paper000-reproduction.md "The paper's claims against the
measurements"): capture-10 with seeds 1, 2, 3, each with the event trigger and with the 1 Hz periodic
broadcast, and capture-20 with seed 1 (event), each `swarmhil run --in-process` for 550 s at the
paper's step and read back by `swarmhil report` (claims/paper000_stack.py `stack_run`).

Seed 1 of capture-10 is the run of docs/paper000.md's "Case (i) over the link" (sources
`p000.stack.event` / `p000.stack.periodic`); the others are sources here (tier `study`: 170 s of CPU
per capture-10 run, about 400 s for capture-20 on this machine). A seed changes the initial
positions and attitudes and the sensor noise (missions/p000_capture/seeds.py).
"""
from __future__ import annotations

import statistics
from typing import Any, Callable

from swarmhil.claims.missions import mission_test_module
from swarmhil.claims.model import Claim, Row, Source, Table, Tol, Values
from swarmhil.claims.paper000_stack import POLICIES, stack_run

DOC = "docs/paper000-reproduction.md"
AUTO = Tol(auto=True)
SEEDS = (1, 2, 3)
ENCLOSURE_S = 326.0  # the paper's enclosure by ~218-326 s (Fig. 3)
R_BUFFER_M = 1.0  # the buffer shell the paper's agents respect
SHELL_SPREAD_M = 1.0  # final signed distances within this of each other: a hovering shell
SETTLE_QUICK_S = 30.0  # "decay quickly": below 1 deg within this after chase entry
ALL_BYTES_SAVED = 0.75  # below this share of the 1 Hz run's total bytes the event trigger saves on the link as a whole
MODULE = "test_p000_closed_loop"


def run_source(case: str, seed: int, policy: str) -> str:
    """The source holding one run: case "i" (capture-10) or "ii" (capture-20)."""
    if case == "i" and seed == 1:
        return f"p000.stack.{policy}"
    return f"p000.repro.{case}-s{seed}-{policy}"


def _run(name: str, seed: int, policy: str) -> Callable[[Any], dict[str, Any]]:
    return lambda _get: stack_run(POLICIES[policy], name=name, seed=seed)


NEW_RUNS = [("i", "capture-10", s, p) for s in SEEDS if s != 1 for p in POLICIES] + [("ii", "capture-20", 1, "event")]
CASE_I = [run_source("i", s, p) for s in SEEDS for p in POLICIES]


def across_seeds(get: Callable[[str], dict[str, Any]]) -> dict[str, Any]:
    """Case (i) over its seeds: extremes of the run figures and the message ratios (mean, sample std)."""
    ev = [get(run_source("i", s, "event")) for s in SEEDS]
    per = [get(run_source("i", s, "periodic")) for s in SEEDS]
    r1hz = [e["state_tx"] / p["state_tx"] for e, p in zip(ev, per)]
    rev = [e["ratio_every_step"] for e in ev]
    rall = [e["all_tx_bytes"] / p["all_tx_bytes"] for e, p in zip(ev, per)]
    lm = [e["landmark_tx_bytes"] / e["state_tx_bytes"] for e in ev]
    out: dict[str, Any] = {
        "final_min_m": min(e["final_min_m"] for e in ev), "final_max_m": max(e["final_max_m"] for e in ev),
        "centre_err_max_mm": max(e["centre_err_max_mm"] for e in ev),
        "pointing_final_max_deg": max(e["pointing_final_max_deg"] for e in ev),
        "settle_max_s": max(e["pointing_settle_after_chase_max_s"] for e in ev),
        "body_rate_max_dps": max(e["body_rate_max_dps"] for e in ev),
        "landmark_over_state_mean": statistics.fmean(lm),
    }
    for key, xs in (("r1hz", r1hz), ("revery", rev), ("rall", rall)):
        out |= {f"{key}_mean": statistics.fmean(xs), f"{key}_std": statistics.stdev(xs),
                f"{key}_min": min(xs), f"{key}_max": max(xs)}
    return out


SOURCES = [Source(f"p000.repro.{case}-s{seed}-{policy}", "study", _run(name, seed, policy),
                  f"python -m swarmhil.missions.p000_capture.seeds deploy/scenarios/{name}.toml {seed} S.toml && swarmhil run "
                  f"S.toml --in-process" + "".join(f" --set '{x}'" for x in POLICIES[policy]) + " && swarmhil report RUN")
           for case, name, seed, policy in NEW_RUNS]
SOURCES.append(Source("p000.repro.seeds", "study", across_seeds, "case (i) over seeds 1-3 (derived)",
                      uses=tuple(CASE_I)))

# (result field, claim suffix, format) of each event run
RUN_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("n_agents", "agents", "d"), ("n_chase", "chase", "d"), ("entry_last_s", "entry-last", ".2f"),
    ("min_pair_m", "min-pair", ".2f"), ("min_surface_m", "min-surface", ".2f"),
    ("final_min_m", "final-min", ".2f"), ("final_max_m", "final-max", ".2f"),
    ("n_estimates", "estimates", "d"), ("axes_within_2pct", "within-2pct", "d"), ("axes_err_max_pct", "axes-worst", ".2f"),
    ("centre_err_max_mm", "centre-max", ".1f"), ("pointing_final_max_deg", "pointing-max", ".2f"),
    ("pointing_settle_after_chase_max_s", "settle-max", ".1f"), ("body_rate_max_dps", "rate-max", ".0f"),
    ("ratio_every_step", "ratio-every", ".3f"), ("ratio_1hz_same_run", "ratio-1hz", ".2f"),
)
SEED_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("final_min_m", "final-min", ".2f"), ("final_max_m", "final-max", ".2f"), ("centre_err_max_mm", "centre-max", ".1f"),
    ("pointing_final_max_deg", "pointing-max", ".2f"), ("settle_max_s", "settle-max", ".1f"),
    ("body_rate_max_dps", "rate-max", ".0f"), ("landmark_over_state_mean", "lm-over-state", ".1f"),
    *[(f"{k}_{s}", f"{k}-{s}", fmt) for k, fmt, stats in (("r1hz", ".2f", ("mean", "std", "min", "max")),
                                                           ("revery", ".3f", ("mean", "std")), ("rall", ".2f", ("mean",)))
      for s in stats],
)


def _get(field: str) -> Callable[[Values], Any]:
    return lambda s: s[field]


def _id(case: str, seed: int, suffix: str) -> str:
    return f"p000.repro.{case}{seed}.{suffix}"


# case (i) shows these per seed (the rest over its seeds, `p000.repro.seeds`); case (ii) shows all
PER_SEED = ("agents", "chase", "entry-last", "min-pair", "min-surface", "estimates", "within-2pct", "axes-worst")
CLAIMS = [Claim(_id(case, seed, suffix), run_source(case, seed, "event"), _get(field), AUTO,
                f"paper 000 on the stack, case ({case}) seed {seed}, event trigger: {field}", fmt)
          for case, seeds in (("i", SEEDS), ("ii", (1,))) for seed in seeds for field, suffix, fmt in RUN_FIELDS
          if case == "ii" or suffix in PER_SEED]
CLAIMS += [Claim(f"p000.repro.seeds.{suffix}", "p000.repro.seeds", _get(field), AUTO,
                 f"paper 000 on the stack, case (i) over seeds 1-3: {field}", fmt) for field, suffix, fmt in SEED_FIELDS]


def _i(suffix: str) -> str:
    """Case (i)'s three seeds' values of a claim, in the cell's order."""
    return " / ".join("{" + _id("i", s, suffix) + "}" for s in SEEDS)


def _ii(suffix: str) -> str:
    return "{" + _id("ii", 1, suffix) + "}"


def _s(suffix: str) -> str:
    return "{p000.repro.seeds." + suffix + "}"


def _vals(v: Values, suffix: str) -> list[float]:
    return [float(v[_id(c, s, suffix)]) for c, seeds in (("i", SEEDS), ("ii", (1,))) for s in seeds]  # type: ignore[arg-type]


def _v_chase(v: Values) -> str:
    if _vals(v, "chase") != _vals(v, "agents"):
        return "not reproduced: some agents stay in search"
    return "reproduced" if max(_vals(v, "entry-last")) <= ENCLOSURE_S else "not reproduced: enclosure later than Fig. 3"


def _v_spacing(v: Values) -> str:
    return "reproduced" if min(_vals(v, "min-pair")) > mission_test_module(MODULE).SAFETY_DISTANCE_M else "not reproduced"


def _v_buffer(v: Values) -> str:
    d = min(_vals(v, "min-surface"))
    if d >= R_BUFFER_M:
        return "reproduced"
    return ("partly: never inside the target, but agents enter the buffer shell" if d > 0
            else "not reproduced: inside the target")


def _v_shell(v: Values) -> str:
    lo = min(float(v["p000.repro.seeds.final-min"]), float(v[_id("ii", 1, "final-min")]))  # type: ignore[arg-type]
    hi = max(float(v["p000.repro.seeds.final-max"]), float(v[_id("ii", 1, "final-max")]))  # type: ignore[arg-type]
    if hi - lo <= SHELL_SPREAD_M:
        return "reproduced"
    return "partly: crowding (trap 8) holds some agents metres outside the shell"


def _v_axes(v: Values) -> str:
    return "reproduced (within 2 %)" if _vals(v, "within-2pct") == _vals(v, "agents") else "not reproduced"


def _worst(v: Values, suffix: str) -> float:
    """The largest of case (i)'s value over its seeds (`p000.repro.seeds`) and case (ii)'s."""
    return max(float(v[f"p000.repro.seeds.{suffix}"]), float(v[_id("ii", 1, suffix)]))  # type: ignore[arg-type]


def _v_attitude(v: Values) -> str:
    if _worst(v, "pointing-max") >= 1.0:
        return "not reproduced: pointing error above 1° at the end"
    if _worst(v, "settle-max") <= SETTLE_QUICK_S:
        return "reproduced"
    return "partly: small in the end; \"quickly\" is tens of seconds with the saturated PD (trap 2)"


def _v_messages(v: Values) -> str:
    saved = float(v["p000.repro.seeds.r1hz-max"]) < 1.0 and float(v[_id("ii", 1, "ratio-1hz")]) < 1.0  # type: ignore[arg-type]
    if not saved:
        return "not reproduced"
    total = float(v["p000.repro.seeds.rall-mean"]) < ALL_BYTES_SAVED  # type: ignore[arg-type]
    return "reproduced for the state broadcasts" + ("" if total else "; not for the total link traffic")


ROWS = (
    Row(("agents go from search to chase; \"by approximately 200–300 s most active agents have converged\" (Figs. 3, 8)",
         " / ".join("{" + _id("i", k, "chase") + "} of {" + _id("i", k, "agents") + "}" for k in SEEDS)
         + f" in chase; last entry {_i('entry-last')} s",
         f"{_ii('chase')} of {_ii('agents')} in chase; last entry {_ii('entry-last')} s"), _v_chase),
    Row(("\"maintaining safe inter-agent spacing\"", f"min pair distance {_i('min-pair')} m", f"{_ii('min-pair')} m"),
        _v_spacing),
    Row(("\"respecting the target buffer shell\" (R_buffer = 1 m)", f"min true signed distance {_i('min-surface')} m",
         f"{_ii('min-surface')} m"), _v_buffer),
    Row(("\"forms a distributed hovering pattern around its body\"",
         f"final signed distances {_s('final-min')}–{_s('final-max')} m (all seeds)",
         f"{_ii('final-min')}–{_ii('final-max')} m"), _v_shell),
    Row(("semi-axes estimates settle near the truth (Figs. 7, 12)",
         f"last sorted estimate within 2 %: {_i('within-2pct')} of {_i('estimates')} agents, worst {_i('axes-worst')} %; "
         f"centre error ≤ {_s('centre-max')} mm",
         f"{_ii('within-2pct')} of {_ii('estimates')} within 2 %, worst {_ii('axes-worst')} %; centre error ≤ "
         f"{_ii('centre-max')} mm", ), _v_axes, params=("2",)),
    Row(("attitude errors \"decay quickly and remain small\" (Figs. 5, 10)",
         f"final pointing error ≤ {_s('pointing-max')}°; below 1° for good {_s('settle-max')} s after chase entry "
         f"(worst agent); body rates up to {_s('rate-max')}°/s",
         f"≤ {_ii('pointing-max')}°; below 1° {_ii('settle-max')} s after chase entry (worst); rates up to "
         f"{_ii('rate-max')}°/s"), _v_attitude, params=("1",)),
    Row(("event triggering avoids continuous communication; fewer messages than periodic (Figs. 6, 11)",
         f"state packets vs the 1 Hz run of the same seed {_s('r1hz-mean')} ± {_s('r1hz-std')} ({_s('r1hz-min')}–"
         f"{_s('r1hz-max')}, 3 seeds); vs one per chase agent-step {_s('revery-mean')} ± {_s('revery-std')}; all bytes "
         f"vs the 1 Hz run {_s('rall-mean')} (landmark pooling: {_s('lm-over-state')}× the state bytes)",
         f"vs every step {_ii('ratio-every')}; vs 1 Hz of its chase time {_ii('ratio-1hz')}"), _v_messages,
        params=("1", "3")),
)
TABLES = [Table("paper000-repro", DOC, ("paper's claim (§4.2–4.3)", "case (i), 10 agents, seeds 1 / 2 / 3",
                                         "case (ii), 20 agents, seed 1", "verdict"), ROWS, measured=(1, 2),
                verdict_col=3)]
