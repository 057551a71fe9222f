"""Report section `faults` (issue 27): the run's `[[fault]]` schedule and when each fault started and
ended, read from the recording's `faults` topic (Events fault_start / fault_end, plant/node.py)."""
from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.run_config import camera_from_config
from swarmhil.dashboards.run_metrics import SERIES
from swarmhil.dashboards.sections import (SectionContext, SectionResult, controllers_of, error_metrics_for,
                                 register_section)
from swarmhil.plant.sensors import visibility_series, weak_components


def read_events(mcap: Path, topic: str, kinds: tuple[str, ...] | None = None) -> list[Any]:
    """The swarmhil.v1.Event messages of one topic (`event`, `faults`), in log-time order, with the
    standard reader; `kinds`: only those."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(mcap, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m for _s, _c, _msg, m in reader.iter_decoded_messages(topics=[topic])
                if kinds is None or m.kind in kinds]


def table(head: list[str], rows: list[list[Any]]) -> str:
    """An escaped HTML table."""
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    trs = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{trs}</table>"


def recovery(t_s: np.ndarray, delta_v_mps: np.ndarray, n_components: np.ndarray | None, start_s: float,
             end_s: float | None) -> dict[str, Any]:
    """What the swarm did over a fault's window [start_s, end_s) and after it, from the truth:
    ΔV spent by the whole swarm in the window; with a visibility digraph (paper 002's cameras), its
    weakly connected components when the fault starts, the most during the window, when it ends,
    and the time from the window's end to the first step with one component (0: connected at the
    end; None: never again in the run). `n_components` (T,) per recorded step t_s."""
    stop = float(t_s[-1]) if end_s is None else float(end_s)
    k0 = int(np.searchsorted(t_s, start_s - 1e-9))
    k1 = min(int(np.searchsorted(t_s, stop - 1e-9)), len(t_s) - 1)
    out: dict[str, Any] = {"delta_v_in_window_mps": float(delta_v_mps[k1].sum() - delta_v_mps[k0].sum())}
    if n_components is not None and k0 < len(t_s):
        during = n_components[k0:max(k1, k0 + 1)]
        after = np.flatnonzero(n_components[k1:] == 1)
        out.update({"components_at_start": int(n_components[k0]), "components_max_in_window": int(during.max()),
                    "components_at_end": int(n_components[k1]),
                    "time_to_reconnect_s": float(t_s[k1 + after[0]] - t_s[k1]) if after.size else None})
    return out


def excursion(t_s: np.ndarray, values: np.ndarray, start_s: float, end_s: float | None) -> dict[str, Any]:
    """A mission error metric around a fault's window [start_s, end_s): its value when the fault
    starts, the largest in the window, its value at the end, the largest after it, its value when
    the run ends, and the excursion (largest in the window minus the value at the start)."""
    stop = float(t_s[-1]) if end_s is None else float(end_s)
    k0 = min(int(np.searchsorted(t_s, start_s - 1e-9)), len(t_s) - 1)
    k1 = min(int(np.searchsorted(t_s, stop - 1e-9)), len(t_s) - 1)
    during = values[k0:max(k1, k0 + 1)]
    out = {"at_start": float(values[k0]), "max_in_window": float(during.max()), "at_end": float(values[k1]),
           "excursion": float(during.max() - values[k0])}
    if k1 + 1 < len(values):
        out["max_after"] = float(values[k1 + 1:].max())
    out["at_run_end"] = float(values[-1])
    return out


SWARM_GRAPH_CONTROLLERS = {"null", "drift-null", "sabatini"}  # paper 002's laws: the swarm is its camera graph


def has_swarm_graph(config: dict[str, Any]) -> bool:
    """Whether a run's swarm is held together by its camera-visibility digraph (paper 002 runs):
    then "recovered" means that graph is one weakly connected component again."""
    return camera_from_config(config) is not None and controllers_of(config) <= SWARM_GRAPH_CONTROLLERS


def visibility_components(ctx: SectionContext) -> np.ndarray | None:
    """Components of the recorded camera-visibility digraph per step (paper 002 runs), else None."""
    cam = camera_from_config(ctx.config) if ctx.truth is not None else None
    if cam is None or not has_swarm_graph(ctx.config):
        return None
    return weak_components(visibility_series(ctx.truth.position_m, cam, ctx.truth.alive))[0]


@register_section("faults", applies=lambda cfg: bool(cfg.get("faults")))
def faults(ctx: SectionContext) -> SectionResult:
    events = read_events(ctx.mcap, "faults", ("fault_start", "fault_end"))
    seen: dict[str, dict[str, Any]] = {}
    for e in events:
        seen.setdefault(e.subject, {})[e.kind] = round(e.header.t, 9)
    rows, metrics = [], {}
    ncomp = visibility_components(ctx)
    errors = [fn(ctx) for _n, fn in error_metrics_for(ctx.config)] if ctx.truth is not None else []
    for f in ctx.config["faults"]:
        name = f["name"]
        what = {k: v for k, v in f.items() if k not in ("name", "kind", "start_s", "end_s")}
        started, ended = seen.get(name, {}).get("fault_start"), seen.get(name, {}).get("fault_end")
        rec = recovery(ctx.truth.t_s, ctx.truth.delta_v_mps, ncomp, f["start_s"], f["end_s"]) \
            if ctx.truth is not None and started is not None else {}
        for err in errors if started is not None else ():
            for k, v in excursion(err.t_s, err.values, f["start_s"], f["end_s"]).items():
                rec[f"{err.name} {k} [{err.unit}]"] = v
        rows.append([name, f["kind"], json.dumps(what), f["start_s"], f["end_s"] if f["end_s"] is not None else "run end",
                     "no" if started is None else started, "-" if ended is None else ended,
                     ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in rec.items())])
        metrics[name] = {"kind": f["kind"], "started_t_s": started, "ended_t_s": ended, **rec}
    intro = (f"<p>{len(ctx.config['faults'])} faults scheduled (docs/faults.md); started and ended: the simulated times "
             f"of their events on the recording's <code>faults</code> topic; recovery: from the truth "
             f"(dashboards/sections/faults.py <code>recovery</code>): the swarm's ΔV in the window and, for paper 002's "
             f"camera swarms, the visibility digraph's weakly connected components and the time from the fault's end "
             f"to one component; where the mission's section defines an error metric "
             f"({html.escape(', '.join(e.name for e in errors)) or 'none in this run'}), its value at the fault's start, "
             f"largest in the window, at the end and largest after it (<code>excursion</code>).</p>")
    return SectionResult("Faults", metrics, [], intro + table(
        ["fault", "kind", "target and parameters", "start [s]", "end [s]", "started at [s]", "ended at [s]",
         "recovery (truth)"], rows))


def drawn_fault_recovery(drawn: list[dict[str, Any]], config: dict[str, Any], run_dir: Path) -> list[dict[str, Any]]:
    """A fault campaign's run (deploy/campaign.py): each drawn fault table with its `recovery` from
    the run's metric series (dashboards/run_metrics.py SERIES: t_s, total ΔV, components; the
    components only where the swarm has a visibility graph), its end, whether it ended inside the
    run, and the run's end."""
    series = np.load(Path(run_dir) / SERIES)
    t_s, dv = series["t_s"], series["delta_v_total_mps"][:, None]
    ncomp = series["n_components"] if has_swarm_graph(config) else None
    out = []
    for f in drawn:
        end_s = f["start_s"] + f["duration_s"]
        ended = end_s <= float(t_s[-1])
        rec = recovery(t_s, dv, ncomp, f["start_s"], end_s if ended else None)
        out.append({**f, "end_s": end_s, "ended_in_run": ended, "run_end_s": float(t_s[-1]), **rec})
    return out
