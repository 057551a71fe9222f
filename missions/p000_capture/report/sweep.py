"""Tables of docs/paper000-reproduction.md from paper-000 run directories (issue 12).

Each run directory is named `c<agents>-s<seed>-<policy>[-mp]` (policy: event, 1hz, every, literal)
and has been through `swarmhil report` (summary.json metrics["p000-capture"], the section
missions/p000_capture/report/__init__.py). Prints, per case: the outcome of every run, and the message
reduction of the event trigger against the every-step and 1 Hz runs of the same seed (the link's
own counters: `p000-state` tx packets and payload bytes), with mean ± sample standard deviation
and the range over seeds.

    python -m swarmhil.missions.p000_capture.report.sweep RUNS_PARENT_DIR
    python -m swarmhil.missions.p000_capture.report.sweep --closest RUN_DIR [RUN_DIR ...]   # what happened at the closest approach
    python -m swarmhil.missions.p000_capture.report.sweep --compare RUN_A RUN_B              # bit for bit, e.g. multi- vs in-process
"""
from __future__ import annotations

import json
import re
import statistics
import sys
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.truth_io import read_truth
from swarmhil.missions.p000_capture.contract import Ellipsoid, dcm, surface_frame
from swarmhil.missions.p000_capture.report import axes_error, centroid_error, pair_distance, read_capture, target_axes

NAME = re.compile(r"^c(?P<n>\d+)-s(?P<seed>\d+)-(?P<policy>event|1hz|every|literal)(?P<mp>-mp)?$")


def load_runs(parent: Path) -> list[dict[str, Any]]:
    """One row per reported run directory under `parent` whose name matches NAME."""
    rows = []
    for d in sorted(Path(parent).iterdir()):
        m = NAME.match(d.name)
        f = d / "summary.json"
        if not m or not f.is_file():
            continue
        s = json.loads(f.read_text())
        met = (s.get("metrics") or {}).get("p000-capture")
        if met is None:
            continue
        lt = met["link"]["per_type"]
        rows.append({
            "dir": d.name, "case": int(m["n"]), "seed": int(m["seed"]), "policy": m["policy"],
            "mp": bool(m["mp"]), "wall_s": float(s.get("wall_s", float("nan"))), "met": met,
            "state_tx": lt.get("p000-state", {}).get("tx_messages", 0),
            "state_bytes": lt.get("p000-state", {}).get("tx_payload_bytes", 0),
            "state_rx_bytes": lt.get("p000-state", {}).get("rx_payload_bytes", 0),
            "lm_bytes": lt.get("p000-landmarks", {}).get("tx_payload_bytes", 0),
            "lm_rx_bytes": lt.get("p000-landmarks", {}).get("rx_payload_bytes", 0),
        })
    return rows


def spread(xs: list[float], fmt: str = "{:.3g}") -> str:
    """mean ± sample std (min–max) over seeds; one value as is."""
    if not xs:
        return "—"
    if len(xs) == 1:
        return fmt.format(xs[0])
    return (f"{fmt.format(statistics.mean(xs))} ± {fmt.format(statistics.stdev(xs))} "
            f"({fmt.format(min(xs))}–{fmt.format(max(xs))}, n = {len(xs)})")


def outcome_table(rows: list[dict[str, Any]]) -> str:
    head = ("| run | in chase at end | last chase entry [s] | min true signed distance [m] | min est. distance [m] "
            "| min pair [m] | axes err worst [%] (≤ 2 %) | centroid err worst [m] | pointing worst [deg] "
            "| pointing < 1° after chase entry, worst [s] | max body rate [°/s] | state tx (B) | landmark tx B | wall [s] |")
    out = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        m = r["met"]
        n = len(m["agents"])
        ent = max(m["chase_entry_s"].values()) if m["chase_entry_s"] else float("nan")
        ax = m.get("axes_final_rel_err_max")
        out.append(
            f"| {r['dir']} | {m['in_chase_at_end']}/{n} | {ent:.1f} | {m['min_surface_m']:.2f} | "
            f"{m.get('min_surface_est_m', float('nan')):.2f} | {m['min_pair_m']:.2f} | "
            f"{'—' if ax is None else f'{100 * ax:.2f}'} ({m.get('axes_within_2pct', 0)}/{m.get('agents_with_estimate', 0)}) | "
            f"{m.get('centroid_final_err_max_m') or float('nan'):.3f} | {m.get('pointing_final_max_deg', float('nan')):.2f} | "
            f"{max((m.get('pointing_settle_after_chase_s') or {'': float('nan')}).values()):.0f} | "
            f"{m.get('max_body_rate_dps', float('nan')):.0f} | "
            f"{r['state_tx']} ({r['state_bytes']}) | {r['lm_bytes']} | {r['wall_s']:.0f} |")
    return "\n".join(out)


def reduction_table(rows: list[dict[str, Any]], case: int) -> str:
    """Event trigger vs the every-step and 1 Hz runs of the same seed, and vs the same run's
    counterfactual schedules (one packet per chase agent-step / agent-second)."""
    by = {(r["seed"], r["policy"]): r for r in rows if r["case"] == case and not r["mp"]}
    seeds = sorted({s for s, p in by if p == "event"})
    cols: dict[str, list[float]] = {k: [] for k in (
        "event", "every", "1hz", "ev/every", "ev/1hz", "evB/1hzB", "ev_rx/1hz_rx", "cf_every", "cf_1hz", "all/1hz_all")}
    for s in seeds:
        e = by[(s, "event")]
        cols["event"].append(e["state_tx"])
        cols["cf_every"].append(e["met"]["every_step_ratio"])
        cols["cf_1hz"].append(e["met"]["hz1_ratio"])
        if (s, "every") in by:
            cols["every"].append(by[(s, "every")]["state_tx"])
            cols["ev/every"].append(e["state_tx"] / by[(s, "every")]["state_tx"])
        if (s, "1hz") in by:
            p = by[(s, "1hz")]
            cols["1hz"].append(p["state_tx"])
            cols["ev/1hz"].append(e["state_tx"] / p["state_tx"])
            cols["evB/1hzB"].append(e["state_bytes"] / p["state_bytes"])
            cols["ev_rx/1hz_rx"].append(e["state_rx_bytes"] / p["state_rx_bytes"])
            cols["all/1hz_all"].append((e["state_bytes"] + e["lm_bytes"]) / (p["state_bytes"] + p["lm_bytes"]))
    label = {
        "event": "event-triggered state packets sent", "every": "every-step run: state packets sent",
        "1hz": "1 Hz run: state packets sent", "ev/every": "event / every-step (separate runs, same seed)",
        "ev/1hz": "event / 1 Hz (separate runs, same seed)", "evB/1hzB": "event / 1 Hz, state bytes sent",
        "ev_rx/1hz_rx": "event / 1 Hz, state bytes delivered (rx)",
        "all/1hz_all": "event / 1 Hz, all bytes sent (state + landmark pooling)",
        "cf_every": "event / one packet per chase agent-step of the same run",
        "cf_1hz": "event / one packet per chase agent-second of the same run"}
    out = [f"| case ({'i' if case == 10 else 'ii'}), {case} agents, seeds {seeds} | mean ± std (min–max, n) |", "|---|---|"]
    for k, xs in cols.items():
        out.append(f"| {label[k]} | {spread(xs, '{:.0f}' if k in ('event', 'every', '1hz') else '{:.3f}')} |")
    return "\n".join(out)


def closest_approach(run_dir: Path, every: int = 1) -> dict[str, Any]:
    """The closest approach to the TRUE surface over all agents and steps (every `every`-th step), and
    what the agent believed then: its mode, its signed distance to its ESTIMATED surface (telemetry),
    its centroid and worst sorted-axis errors, its speed toward the true surface (normal component,
    relative to the target's motion) and its nearest neighbour; plus, over every chase step of every
    agent, the error of the estimated distance (estimated − true) and the largest inward speed."""
    run_dir = Path(run_dir)
    summ = json.loads((run_dir / "summary.json").read_text())
    tr = read_truth(run_dir / "run.mcap")
    ids = list(tr.ids)
    rec = read_capture(run_dir / "run.mcap", ids)
    axes = target_axes(summ["config"])
    tvel = np.gradient(rec.target_pos, tr.t_s, axis=0)
    rows = np.arange(0, len(tr.t_s), every)
    sd = np.empty((len(rows), len(ids)))
    vn = np.empty_like(sd)  # outward normal speed relative to the surface's centre motion
    for r, k in enumerate(rows):
        ell = Ellipsoid(rec.target_pos[k], dcm(rec.target_q[k]), axes)
        for i in range(len(ids)):
            sd[r, i], _x, nrm = surface_frame(ell, tr.position_m[k, i])
            vn[r, i] = float(nrm @ (tr.velocity_mps[k, i] - tvel[k]))
    r0, i0 = np.unravel_index(int(np.argmin(sd)), sd.shape)
    k0 = int(rows[r0])
    est_sd = rec.est_surface[rows]
    chase = np.array([[rec.modes.get(n, {}).get(int(tr.step[k]), "search") != "search" for n in ids] for k in rows])
    err = (est_sd - sd)[chase & np.isfinite(est_sd)]
    pair = pair_distance(tr.position_m[k0:k0 + 1])[0]
    ax_e, c_e = axes_error(rec.est_axes, axes), centroid_error(rec.est_centre, rec.target_pos)
    back = rows[max(0, r0 - int(round(30.0 / (tr.t_s[1] - tr.t_s[0]) / every))):r0 + 1]  # the 30 s before
    # the agent's estimated target velocity (the derivative of its estimated centre, which it propagates
    # with that velocity between fits; fit steps excluded) minus the truth, along its line of sight
    # (positive: the estimated target recedes, so the PD, which tracks v_T + the capped approach
    # speed, closes faster than the cap)
    ks = np.asarray(back)
    ks = ks[(ks > 0) & (ks < len(tr.t_s) - 1)]
    v_hat = (rec.est_centre[ks + 1, i0] - rec.est_centre[ks - 1, i0]) / (tr.t_s[ks + 1] - tr.t_s[ks - 1])[:, None]
    los = rec.target_pos[ks] - tr.position_m[ks, i0]
    los /= np.linalg.norm(los, axis=1, keepdims=True)
    v_err = np.einsum("ki,ki->k", v_hat - tvel[ks], los)
    v_err = v_err[np.isfinite(v_err) & (np.abs(v_err) < 0.5)]  # a jump at a fit is not a velocity
    a_max = summ["config"]["spacecraft"][i0]["max_force_n"] / summ["config"]["spacecraft"][i0]["mass_kg"]
    return {
        "run": run_dir.name, "agent": ids[i0], "t_s": float(tr.t_s[k0]), "true_sd_m": float(sd[r0, i0]),
        "mode": rec.modes.get(ids[i0], {}).get(int(tr.step[k0])), "est_sd_m": float(rec.est_surface[k0, i0]),
        "axes_err": float(ax_e[k0, i0]), "centroid_err_m": float(c_e[k0, i0]),
        "inward_speed_mps": float(-vn[r0, i0]), "max_inward_speed_30s_mps": float(-vn[np.isin(rows, back), i0].min()),
        "nearest_neighbour_m": float(pair[i0].min()),
        "vT_est_err_receding_30s_mps": {"median": float(np.median(v_err)), "max": float(v_err.max())}
        if len(v_err) else None,
        "braking_distance_at_max_inward_speed_m": float((-vn[np.isin(rows, back), i0].min()) ** 2 / (2 * a_max)),
        "chase_est_minus_true_m": {"mean": float(err.mean()), "p1": float(np.percentile(err, 1)),
                                   "p99": float(np.percentile(err, 99))} if len(err) else None,
        "min_est_sd_m": float(np.nanmin(est_sd)) if np.isfinite(est_sd).any() else None,
        "chase_max_inward_speed_mps": float(-vn[chase].min()) if chase.any() else None,
        "agents_below_buffer": int(np.sum(sd.min(axis=0) < 1.0)),
    }


def compare_runs(a: Path, b: Path) -> dict[str, bool]:
    """Field by field equality (exact, NaN = NaN) of two runs' recorded truth (positions, velocities,
    dV, commanded accelerations, attitudes, body rates, the target's pose), telemetry (modes and the
    estimates), isl/tx packets and the channel's link rows, read with the streaming readers only
    (a 550 s case (ii) MCAP is ~0.6 GB: nothing is decoded but these topics)."""
    out: dict[str, bool] = {}
    ta, tb = read_truth(Path(a) / "run.mcap"), read_truth(Path(b) / "run.mcap")
    for f in ("step", "t_s", "position_m", "velocity_mps", "delta_v_mps", "accel_mps2", "alive"):
        out[f"truth.{f}"] = bool(np.array_equal(getattr(ta, f), getattr(tb, f)))
    ca, cb = read_capture(Path(a) / "run.mcap", list(ta.ids)), read_capture(Path(b) / "run.mcap", list(tb.ids))
    for f in ("target_pos", "target_q", "sc_q", "sc_w", "est_axes", "est_centre", "est_surface"):
        out[f] = bool(np.array_equal(getattr(ca, f), getattr(cb, f), equal_nan=True))
    out["modes"] = ca.modes == cb.modes
    out["isl_tx"] = sorted(ca.tx) == sorted(cb.tx)
    sa, sb = (json.loads((Path(d) / "summary.json").read_text()) for d in (a, b))
    out["channel.links"] = sa["channel"]["links"] == sb["channel"]["links"]
    out["steps"] = sa["steps"] == sb["steps"] and len(ta.t_s) == len(tb.t_s)
    return out


def main(argv: list[str]) -> int:
    if argv[:1] == ["--compare"] and len(argv) == 3:
        res = compare_runs(Path(argv[1]), Path(argv[2]))
        print(json.dumps(res))
        return 0 if all(res.values()) else 1
    if argv[:1] == ["--closest"] and len(argv) > 1:
        for d in argv[1:]:
            try:
                print(json.dumps(closest_approach(Path(d), every=2)))
            except (OSError, ValueError, KeyError) as exc:
                print(f"missions.p000_capture.report.sweep: {d}: {exc}", file=sys.stderr)
                return 2
        return 0
    if len(argv) != 1 or not Path(argv[0]).is_dir():
        print("usage: python -m swarmhil.missions.p000_capture.report.sweep RUNS_PARENT_DIR", file=sys.stderr)
        return 2
    rows = load_runs(Path(argv[0]))
    if not rows:
        print(f"missions.p000_capture.report.sweep: no reported c<n>-s<seed>-<policy> runs under {argv[0]}", file=sys.stderr)
        return 2
    print(outcome_table(rows))
    for case in sorted({r["case"] for r in rows}):
        print()
        print(reduction_table(rows, case))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
