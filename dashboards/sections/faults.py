"""Report section `faults` (issue 27): the run's `[[fault]]` schedule and when each fault started and
ended, read from the recording's `faults` topic (Events fault_start / fault_end, plant/node.py)."""
from __future__ import annotations

import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.keys import split_topic
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


def held_reconnection(t_s: np.ndarray, whole: np.ndarray, k_from: int, hold_s: float) -> tuple[int | None, bool]:
    """The first step k >= k_from from which the swarm is whole at every recorded step of
    [t_k, t_k + hold_s], and whether the question is still open at the run's end.

    Returns (k, False) when such a step exists; (None, True) when the swarm is whole from some
    step on to the run's last step but for less than hold_s (the run ended too soon to judge);
    (None, False) when it is split at the run's last step (or never whole after k_from). `whole`
    (T,) bool per recorded step t_s (T,)."""
    idx = np.flatnonzero(np.asarray(whole[k_from:], dtype=bool)) + k_from
    if not idx.size:
        return None, False
    breaks = np.flatnonzero(np.diff(idx) != 1)
    starts, ends = np.r_[idx[0], idx[breaks + 1]], np.r_[idx[breaks], idx[-1]]
    held = t_s[ends] - t_s[starts] >= hold_s - 1e-9
    if held.any():
        return int(starts[int(np.argmax(held))]), False
    return None, bool(ends[-1] == len(t_s) - 1)


OUTCOMES = ("never split", "split and recovered", "not recovered", "not judged")
"""A fault's outcome on a graph (`judge`): the three a campaign counts, and the runs it cannot judge."""


def judge(t_s: np.ndarray, n_components: np.ndarray, k0: int, k1: int, ended: bool, hold_s: float,
          prefix: str = "") -> dict[str, Any]:
    """A fault's effect on a graph of the swarm (camera visibility, or the link's deliveries), from
    its components per recorded step `n_components` (T,) and the fault's window [k0, k1) as
    indices of t_s (k1: the step the window ends at, the run's last step for a fault that lasts to
    the end; `ended`: False when the fault was still on when the run ended).

    - split: more than one component at some step of the window or after it;
    - recovered: True when, after the window, the swarm is whole again and stays whole for hold_s
      (`held_reconnection`); False when it is not by the run's end; None when the swarm never
      split (nothing to recover from) or the run cannot tell (the fault had not ended, or the swarm
      is whole at the run's end but for less than hold_s);
    - time_to_reconnect_s: from the window's end to the start of that held reconnection (0: whole
      at the window's end and stays so), else None;
    - outcome: one of OUTCOMES.
    Keys carry `prefix` (`link_` for the link graph)."""
    during = n_components[k0:max(k1, k0 + 1)]
    split = bool((n_components[k0:] > 1).any())
    recovered: bool | None = None
    ttr: float | None = None
    if not split:
        outcome = "never split"
    elif not ended:
        outcome = "not judged"
    else:
        k, pending = held_reconnection(t_s, n_components == 1, k1, hold_s)
        if k is not None:
            recovered, ttr, outcome = True, float(t_s[k] - t_s[k1]), "split and recovered"
        elif pending:
            outcome = "not judged"
        else:
            recovered, outcome = False, "not recovered"
    return {f"{prefix}components_at_start": int(n_components[k0]), f"{prefix}components_max_in_window": int(during.max()),
            f"{prefix}components_at_end": int(n_components[k1]), f"{prefix}split": split,
            f"{prefix}recovered": recovered, f"{prefix}time_to_reconnect_s": ttr, f"{prefix}outcome": outcome}


def window_steps(t_s: np.ndarray, start_s: float, end_s: float | None) -> tuple[int, int, bool]:
    """A fault's window [start_s, end_s) as indices (k0, k1) of the recorded steps t_s, and whether it
    ended inside the run (end_s None: it lasts to the run's end, k1 the last step, and counts as ended)."""
    stop = float(t_s[-1]) if end_s is None else float(end_s)
    k0 = int(np.searchsorted(t_s, start_s - 1e-9))
    k1 = min(int(np.searchsorted(t_s, stop - 1e-9)), len(t_s) - 1)
    return k0, k1, end_s is None or float(end_s) <= float(t_s[-1]) + 1e-9


def recovery(t_s: np.ndarray, delta_v_mps: np.ndarray, n_components: np.ndarray | None, start_s: float,
             end_s: float | None, hold_s: float, link_components: np.ndarray | None = None) -> dict[str, Any]:
    """What the swarm did over a fault's window [start_s, end_s) and after it, from the truth:
    ΔV spent by the whole swarm in the window; with a visibility digraph (paper 002's cameras), its
    weakly connected components when the fault starts, the most during the window, when it ends,
    and whether the swarm split and recovered (`judge`, held for hold_s); with the link graph's
    components per step (`link_components`, a link fault), the same judged on it, keys `link_*`.
    Series are (T,) per recorded step t_s; end_s None: the fault lasts to the run's end."""
    k0, k1, ended = window_steps(t_s, start_s, end_s)
    out: dict[str, Any] = {"delta_v_in_window_mps": float(delta_v_mps[k1].sum() - delta_v_mps[min(k0, k1)].sum())}
    if k0 >= len(t_s):
        return out
    if n_components is not None or link_components is not None:
        out["hold_s"] = float(hold_s)
    if n_components is not None:
        out.update(judge(t_s, n_components, k0, k1, ended, hold_s))
    if link_components is not None:
        out.update(judge(t_s, link_components, k0, k1, ended, hold_s, prefix="link_"))
    return out


def link_components(t_s: np.ndarray, ids: list[str], sent_t_s: np.ndarray, src: list[str], dst: list[str],
                    window_s: float) -> np.ndarray:
    """Weakly connected components per recorded step (T,) of the link graph built from the link's
    own deliveries: at step t_k spacecraft i and j are joined when a packet of one was delivered to
    the other with its sending time in (t_k - window_s, t_k]. `sent_t_s`, `src`, `dst`: one entry
    per delivery (IslPacket.sent_t, .src, the receiver)."""
    index = {s: i for i, s in enumerate(ids)}
    n, T = len(ids), len(t_s)
    keep = [q for q in range(len(src)) if src[q] in index and dst[q] in index]
    diff = np.zeros((T + 1, n, n), dtype=np.int64)
    if keep:
        sent = np.asarray(sent_t_s, dtype=float)[keep]
        i = np.array([index[src[q]] for q in keep])
        j = np.array([index[dst[q]] for q in keep])
        lo = np.searchsorted(t_s, sent - 1e-9)            # the first step at or after the sending
        hi = np.searchsorted(t_s, sent + window_s - 1e-9)  # the first step window_s or more after it
        np.add.at(diff, (lo, i, j), 1)
        np.add.at(diff, (hi, i, j), -1)
    up = np.cumsum(diff[:T], axis=0) > 0
    return weak_components(up)[0]


def link_window_s(sent_t_s: np.ndarray, src: list[str], step_s: float) -> float:
    """How long one delivery keeps a link up in `link_components`: twice the median interval between
    a spacecraft's successive packets that were delivered (so that one lost packet does not cut the
    link), at least one step."""
    gaps: list[np.ndarray] = []
    sent = np.asarray(sent_t_s, dtype=float)
    srcs = np.asarray(src, dtype=object)
    for s in set(src):
        t = np.unique(sent[srcs == s])
        if t.size > 1:
            gaps.append(np.diff(t))
    gap = float(np.median(np.concatenate(gaps))) if gaps else step_s
    return max(2.0 * gap, float(step_s))


def read_deliveries(mcap: Path) -> tuple[np.ndarray, list[str], list[str]]:
    """(sent_t_s, src, receiver) of every packet the link channel delivered (`isl/rx/<id>` topics)."""
    from mcap.reader import make_reader

    sent: list[float] = []
    src: list[str] = []
    dst: list[str] = []
    with open(mcap, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages():
            parts = split_topic(ch.topic)[1].split("/")
            if len(parts) == 3 and parts[0] == "isl" and parts[1] == "rx":
                p = pb.IslPacket.FromString(m.data)
                sent.append(p.sent_t)
                src.append(p.src)
                dst.append(parts[2])
    return np.asarray(sent, dtype=float), src, dst


def hold_s_of(config: dict[str, Any]) -> float:
    """The run's [recovery].hold_s as resolved (deploy/scenario.py `recovery_hold_s`); a recording
    made before it was resolved: one period of its reference orbit."""
    hold = (config.get("recovery") or {}).get("hold_s")
    if hold is not None:
        return float(hold)
    return 2.0 * math.pi / float(config["orbit"]["mean_motion_radps"])


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
    hold_s = hold_s_of(ctx.config) if ctx.truth is not None else 0.0
    links = link_series(ctx.mcap, ctx.config, ctx.truth.t_s) if ctx.truth is not None else None
    errors = [fn(ctx) for _n, fn in error_metrics_for(ctx.config)] if ctx.truth is not None else []
    for f in ctx.config["faults"]:
        name = f["name"]
        what = {k: v for k, v in f.items() if k not in ("name", "kind", "start_s", "end_s")}
        started, ended = seen.get(name, {}).get("fault_start"), seen.get(name, {}).get("fault_end")
        rec = recovery(ctx.truth.t_s, ctx.truth.delta_v_mps, ncomp, f["start_s"], f["end_s"], hold_s,
                       links if is_link_fault(f) else None) if ctx.truth is not None and started is not None else {}
        for err in errors if started is not None else ():
            for k, v in excursion(err.t_s, err.values, f["start_s"], f["end_s"]).items():
                rec[f"{err.name} {k} [{err.unit}]"] = v
        rows.append([name, f["kind"], json.dumps(what), f["start_s"], f["end_s"] if f["end_s"] is not None else "run end",
                     "no" if started is None else started, "-" if ended is None else ended,
                     ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in rec.items()
                               if k != "hold_s")])
        metrics[name] = {"kind": f["kind"], "started_t_s": started, "ended_t_s": ended, **rec}
    intro = (f"<p>{len(ctx.config['faults'])} faults scheduled (docs/faults.md); started and ended: the simulated times "
             f"of their events on the recording's <code>faults</code> topic; recovery: from the truth "
             f"(dashboards/sections/faults.py <code>recovery</code>): the swarm's ΔV in the window and, for paper 002's "
             f"camera swarms, the visibility digraph's weakly connected components, whether it split (more than one "
             f"component in the window or after it) and recovered (one component again after the window, staying so "
             f"for {hold_s:.6g} s, <code>[recovery].hold_s</code>) and the time from the fault's end to that held "
             f"reconnection; for a link fault the same on the link graph built from the link's own deliveries "
             f"(<code>link_*</code>); where the mission's section defines an error metric "
             f"({html.escape(', '.join(e.name for e in errors)) or 'none in this run'}), its value at the fault's start, "
             f"largest in the window, at the end and largest after it (<code>excursion</code>).</p>")
    return SectionResult("Faults", metrics, [], intro + table(
        ["fault", "kind", "target and parameters", "start [s]", "end [s]", "started at [s]", "ended at [s]",
         "recovery (truth)"], rows))


def is_link_fault(fault: dict[str, Any]) -> bool:
    """A fault of the link (partition, degradation): judged on the link graph too."""
    return str(fault["kind"]).startswith("link_")


def link_series(mcap: Path, config: dict[str, Any], t_s: np.ndarray) -> np.ndarray | None:
    """The link graph's components per recorded step (`link_components`) of a run with link faults
    whose recording holds the link's deliveries; else None."""
    if not any(map(is_link_fault, config.get("faults") or [])):
        return None
    sent, src, dst = read_deliveries(mcap)
    if not sent.size:
        return None
    ids = [s["id"] for s in config.get("spacecraft") or []]
    step_s = float(config["run"]["step_s"])
    return link_components(t_s, ids, sent, src, dst, link_window_s(sent, src, step_s))


def drawn_fault_recovery(drawn: list[dict[str, Any]], config: dict[str, Any], run_dir: Path,
                         hold_s: float | None = None) -> list[dict[str, Any]]:
    """A fault campaign's run (deploy/campaign.py): each drawn fault table with its `recovery` from
    the run's metric series (dashboards/run_metrics.py SERIES: t_s, total ΔV, components; the
    components only where the swarm has a visibility graph), its end, whether it ended inside the
    run, and the run's end; a link fault also on the link graph when the run recorded its deliveries
    (`record = "all"`). `hold_s`: how long the swarm must stay whole (default the run's own)."""
    series = np.load(Path(run_dir) / SERIES)
    t_s, dv = series["t_s"], series["delta_v_total_mps"][:, None]
    ncomp = series["n_components"] if has_swarm_graph(config) else None
    hold = hold_s_of(config) if hold_s is None else float(hold_s)
    mcap = Path(run_dir) / "run.mcap"
    links = link_series(mcap, config, t_s) if mcap.is_file() and any(map(is_link_fault, drawn)) else None
    out = []
    for f in drawn:
        end_s = f["start_s"] + f["duration_s"]
        ended = end_s <= float(t_s[-1])
        rec = recovery(t_s, dv, ncomp, f["start_s"], end_s, hold, links if is_link_fault(f) else None)
        out.append({**f, "end_s": end_s, "ended_in_run": ended, "run_end_s": float(t_s[-1]), **rec})
    return out


def with_baseline_outcomes(faults: list[dict[str, Any]], base_dir: Path) -> list[dict[str, Any]]:
    """Each drawn fault with `baseline_outcome`: the outcome of its window judged the same way on the
    same seed's run without faults (its metric series; not judged where there is none, or for a
    link fault, whose graph a baseline without the fault does not record), so a report can tell
    what the fault did from what the swarm does anyway."""
    path = Path(base_dir) / SERIES
    series = np.load(path) if path.is_file() else None
    out = []
    for f in faults:
        outcome = "not judged"
        if series is not None and "n_components" in series and not str(f["kind"]).startswith("link_") \
                and f.get("hold_s") is not None:
            outcome = recovery(series["t_s"], series["delta_v_total_mps"][:, None], series["n_components"],
                               f["start_s"], f["end_s"], f["hold_s"])["outcome"]
        out.append({**f, "baseline_outcome": outcome})
    return out
