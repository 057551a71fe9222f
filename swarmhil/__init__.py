"""swarmhil for analysis: `swarmhil.load(RUN)` gives a run as pandas data frames (docs/analysis.md).

    import swarmhil
    run = swarmhil.load("runs/demo")
    run.truth        # one row per (step, body): t_s, id, x_m..., vx_mps..., ax_cmd_mps2..., delta_v_mps, roe_*_m, q*
    run.commands     # one row per (step, spacecraft) ActuatorCommand
    run.link         # the link channel's cumulative counters per (sample, src, dst, type); run.link_totals
    run.events       # the event log
    run.metrics_series, run.metrics   # the swarm metrics per step, and the scalar metrics
    run.config       # the resolved configuration the recording carries

The column definitions are in dashboards/frames.py; the same tables are what `swarmhil report RUN`
writes to RUN/report/data/ as Parquet and CSV.
"""
from __future__ import annotations

from swarmhil.dashboards.frames import RunData, load

__all__ = ["RunData", "load"]
