"""swarmhil: every installed module lives under this one name (`swarmhil.agent`, `swarmhil.plant`,
`swarmhil.bus`, `swarmhil.link`, `swarmhil.deploy`, `swarmhil.dashboards`, `swarmhil.missions`,
`swarmhil.claims`; docs/architecture.md "One installed name"). In the repository these are the
top-level folders of the design card; `swarmhil/<name>` links to each.

For analysis, `swarmhil.load(RUN)` gives a run as pandas data frames (docs/analysis.md):

    import swarmhil
    run = swarmhil.load("runs/demo")
    run.truth        # one row per (step, body): t_s, id, x_m..., vx_mps..., ax_cmd_mps2..., delta_v_mps, roe_*_m, q*
    run.commands     # one row per (step, spacecraft) ActuatorCommand
    run.link         # the link channel's cumulative counters per (sample, src, dst, type); run.link_totals
    run.events       # the event log
    run.metrics_series, run.metrics   # the swarm metrics per step, and the scalar metrics
    run.config       # the resolved configuration the recording carries

The column definitions are in dashboards/frames.py; the same tables are what `swarmhil report RUN`
writes to RUN/report/data/ as Parquet and CSV. `load` and `RunData` are imported on first use
(PEP 562): importing `swarmhil.agent` in an agent image loads neither pandas nor the reports.
"""
from __future__ import annotations

from typing import Any

__all__ = ["RunData", "load"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from swarmhil.dashboards import frames  # reports extra (pandas): only when asked for

        return getattr(frames, name)
    raise AttributeError(f"module 'swarmhil' has no attribute {name!r}")
