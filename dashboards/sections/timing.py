"""Report section `timing` (issue 26): each agent's flight-software compute time per step (stimulus in
-> command out, `Telemetry.compute_s` that agent/node.py measures and publishes on `sc/<id>/tm`)
beside the step period and, in real time, the wall deadline step_s / speed (plant/pacing.py RealTime),
read back from the recording with the standard MCAP reader."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section
from swarmhil.dashboards.sections.faults import table

_TM = re.compile(r"(?:^|/)sc/([^/]+)/tm$")  # `sc/<id>/tm`, or the full key of recordings before the contract


def read_compute_times(mcap: Path) -> dict[str, np.ndarray]:
    """{agent id: its compute_s per recorded Telemetry, in log-time order} of every `sc/<id>/tm`
    topic of the recording (none when it holds the truth only)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(mcap, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        channels = summary.channels.values() if summary is not None else []
        topics = sorted({c.topic for c in channels if _TM.search(c.topic)})
        out: dict[str, list[float]] = {}
        if topics:
            for _s, ch, _m, tm in reader.iter_decoded_messages(topics=topics):
                out.setdefault(_TM.search(ch.topic).group(1), []).append(float(tm.compute_s))
    return {sid: np.asarray(v, dtype=float) for sid, v in sorted(out.items())}


def wall_deadline_s(config: dict[str, Any]) -> float | None:
    """The real-time wall deadline of one step, step_s / speed (plant/pacing.py RealTime; the command
    of step k is due at t0 + (k+1) step_s / speed); None in lockstep, where the plant waits."""
    run = config.get("run") or {}
    if run.get("mode", "lockstep") != "realtime":
        return None
    return float(run["step_s"]) / float(run.get("speed", 1.0))


def timing_metrics(compute_s: dict[str, np.ndarray], step_s: float, deadline_s: float | None) -> dict[str, dict[str, Any]]:
    """Per agent: steps, p50 / p99 (numpy's linear interpolation) and max of its compute time per
    step [s], and whether its p99 exceeds the real-time deadline (always False without one)."""
    out = {}
    for sid, x in compute_s.items():
        if x.size == 0:
            continue
        p50, p99 = np.percentile(x, [50.0, 99.0])
        out[sid] = {"steps": int(x.size), "p50_s": float(p50), "p99_s": float(p99), "max_s": float(x.max()),
                    "step_s": step_s, "deadline_s": deadline_s,
                    "p99_over_deadline": bool(deadline_s is not None and p99 > deadline_s)}
    return out


def _ms(x: float) -> str:
    return f"{x * 1e3:.3g}"


@register_section("timing", applies=lambda cfg: True)
def timing(ctx: SectionContext) -> SectionResult:
    run = ctx.config.get("run") or {}
    step_s = float(run.get("step_s") or ctx.summary.get("step_s") or 0.0)
    deadline = wall_deadline_s(ctx.config)
    agents = timing_metrics(read_compute_times(ctx.mcap), step_s, deadline)
    missed = ctx.summary.get("missed_deadlines") or {}
    flagged = sorted(sid for sid, m in agents.items() if m["p99_over_deadline"])
    metrics: dict[str, Any] = {"mode": run.get("mode", "lockstep"), "speed": run.get("speed"), "step_s": step_s,
                               "deadline_s": deadline, "agents": agents, "p99_over_deadline": flagged}
    if not agents:
        return SectionResult("Flight-software timing", metrics, [], "<p>The recording holds no agent telemetry "
                             "(<code>sc/&lt;id&gt;/tm</code>; a truth-only recording): no compute times.</p>")
    if deadline is None:
        when = (f"Lockstep: the plant waits for every command, so there is no wall deadline; the step period is "
                f"{step_s:g} s of simulated time.")
    else:
        when = (f"Real time at speed {float(run.get('speed', 1.0)):g}: the command of step k is due at the wall time "
                f"t0 + (k+1) &times; {_ms(deadline)} ms (step period {step_s:g} s / speed), so a step's compute time "
                f"must stay under {_ms(deadline)} ms. "
                + (f"<b>p99 over the deadline: {', '.join(flagged)}.</b>" if flagged else "Every agent's p99 is within it."))
    rows = [[sid, m["steps"], _ms(m["p50_s"]), _ms(m["p99_s"]), _ms(m["max_s"]), f"{step_s:g}",
             "none (lockstep)" if deadline is None else _ms(deadline), missed.get(sid, 0),
             "P99 OVER DEADLINE" if m["p99_over_deadline"] else ""] for sid, m in agents.items()]
    intro = ("<p>Each agent's wall time per step from stimulus in to command out, as it measured and published it "
             "(<code>Telemetry.compute_s</code> on <code>sc/&lt;id&gt;/tm</code>, agent/node.py); p50 / p99 by linear "
             f"interpolation. {when} Missed deadlines: the plant's count (<code>summary.json</code> "
             "<code>missed_deadlines</code>).</p>")
    return SectionResult("Flight-software timing", metrics, [], intro + table(
        ["agent", "steps", "p50 [ms]", "p99 [ms]", "max [ms]", "step period [s]", "wall deadline [ms]",
         "missed deadlines", "flag"], rows))
