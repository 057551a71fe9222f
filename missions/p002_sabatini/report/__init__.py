"""Paper 002's report section (behavioural swarm keeping, Sabatini et al.): its metrics table and
Figs. 7-22, for runs flown only with its controllers (`null`, `drift-null`, `sabatini`) and for
recordings that carry no configuration (older runs, all of paper 002). Registered as `p002-swarm`
(dashboards/sections/); imports its contract and the report kit, never its flight software.

The numbers are its metrics hook's (`metrics.py` in this package, registered with
dashboards/metrics.py `register_mission_metrics` for the same runs), kept where they have always
been (summary.json["metrics"]: `connectivity`, `closest_visible_steady`, ...); this section shows
them (issue 25: the overview of every report is mission-neutral, paper 002's ROE metrics are paper
002's). Figures with one line per spacecraft are LineFigure specs (dashboards/figstyle.py): drawn
static (PNG, SVG, PDF) and interactive (Plotly, dashboards/interactive.py) from the same data.

Split by job like dashboards/navreport/ (docs/architecture.md), each module importing only those
before it: `metrics` (the analysis: its metrics hook, pure functions of the truth arrays; there is
no `read`, the section reads nothing beyond the reporter's truth), `figures` (Figs. 7-22:
LineFigure specs and the matplotlib digraphs), `page` (the table, the captions and the section).
This package imports `metrics` and `page`, so that the reporter's discovery (bus/discovery.py
`import_role("report")`) registers the metrics hook and the section.
"""
from swarmhil.missions.p002_sabatini.report import metrics, page  # noqa: F401 - register the metrics hook and the section (discovery imports this package)
