"""Tables of docs/paper000-reproduction.md from paper-000 run directories (issue 12).

Each run directory is named `c<agents>-s<seed>-<policy>[-mp]` (policy: event, 1hz, every, literal)
and has been through `swarmhil report` (summary.json metrics["p000-capture"], the section
dashboards/sections/p000.py). Prints, per case: the outcome of every run, and the message
reduction of the event trigger against the every-step and 1 Hz runs of the same seed (the link's
own counters: `p000-state` tx packets and payload bytes), with mean ± sample standard deviation
and the range over seeds.

    python -m dashboards.p000_sweep RUNS_PARENT_DIR
"""
from __future__ import annotations

import json
import re
import statistics
import sys
from pathlib import Path
from typing import Any

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
            "| state tx (B) | landmark tx B | wall [s] |")
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


def main(argv: list[str]) -> int:
    if len(argv) != 1 or not Path(argv[0]).is_dir():
        print("usage: python -m dashboards.p000_sweep RUNS_PARENT_DIR", file=sys.stderr)
        return 2
    rows = load_runs(Path(argv[0]))
    if not rows:
        print(f"p000_sweep: no reported c<n>-s<seed>-<policy> runs under {argv[0]}", file=sys.stderr)
        return 2
    print(outcome_table(rows))
    for case in sorted({r["case"] for r in rows}):
        print()
        print(reduction_table(rows, case))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
