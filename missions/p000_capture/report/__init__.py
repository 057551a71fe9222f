"""Report section of paper 000 (issue 12): a swarm searches, fits and encloses a tumbling ellipsoidal
target, broadcasting its state on an event trigger (docs/paper000.md).

Applies to runs whose spacecraft flew "p000-capture". Everything comes from the recording:
spacecraft positions, accelerations and dV from ctx.truth; the target's pose and attitude and the
spacecraft attitudes from the raw Truth messages (standard mcap reader); each agent's mode from its
`sc/<id>/tm` telemetry; the packets sent from the `isl/tx/<id>` topics; the link's per-type counters
from summary.json["channel"]; from ctx.config the target's semi-axes and the controller's params
(controller.params merged with each spacecraft's params, as deploy/scenario.py).

Signed distances use the room's closest-point routine (missions/p000_capture/contract.py) on
the TRUE target. The pure functions of analysis.py (`surface_distance`, `chase_entry`,
`link_by_type`, `pair_distance`) are also what tests/missions/test_p000_stack.py computes its
figures with.

Split by job like dashboards/navreport/ (docs/architecture.md), each module importing only those
before it: `read` (the recording's target, attitudes, telemetry and packets; the target's axes and
the controller's params from the configuration), `analysis` (signed and pair distances, chase
entries, link counters, pointing and estimate errors, the section's metrics), `figures`
(matplotlib), `page` (the table, the section and the landmark kind's registration). `sweep.py`,
the tables over a sweep's runs (`python -m swarmhil.missions.p000_capture.report.sweep`), imports
`read` and `analysis` only. This package imports `page` alone, so that the reporter's and the
viewer's discovery (bus/discovery.py `import_role("report")`) registers the section and the
landmark kind.
"""
from swarmhil.missions.p000_capture.report import page  # noqa: F401 - registers the section and the landmark kind (discovery imports this package)
