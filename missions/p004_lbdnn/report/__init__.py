"""Report section of paper 004 (issue 15): six servicers converge on a defunct spacecraft.

Applies to runs flown with controller `p004-lbdnn`. Everything comes from the recording: the
servicers from ctx.truth (dashboards/truth_io.py, scenario frame = the defunct craft's LVLH for
deploy/scenarios/servicing-6.toml), the defunct craft from the raw Truth messages of ctx.mcap (a
body, not a spacecraft), the graph / C_i / b_i from the controller's params in ctx.config
(missions/p004_lbdnn/contract.py mission_from_params), link bytes from summary.json's channel
totals.

Metrics (`summary.json["metrics"]["p004-servicing"]`): the tracking errors ‖e_i‖ = ‖q0 − q_i‖
(frame-independent) per servicer and over the swarm — mean and max after STEADY_FROM_S, the time
from which all stay below TRACK_LEVEL_M —, the control effort ‖u_i‖ (the command applied over
[t_k, t_k+1), after the actuator limit; peak, mean after STEADY_FROM_S), Δv per servicer,
λ_min(H) of the configured graph and C_i, and the link's bytes.

Figures like the paper's: the servicers' paths relative to the defunct craft (Fig. 2: 3D over the
first PATH_WINDOW_S, with the three planar projections over the whole run), the tracking errors
(Fig. 4) and the control effort with the cumulative Δv (not a figure of the paper). Fig. 3, the
neighbourhood velocity-estimation error ‖ζ̃_i‖, needs the observers' state, which is not in the truth.

The scalar figures (`servicing_figures`, `first_time_below`, `tracking_errors`) are shared with
tests/missions/test_p004_stack.py, which computes them from its own reading of the MCAP.

Split by job like dashboards/navreport/ (docs/architecture.md), each module importing only those
before it: `read` (the defunct craft's truth, the servicers and the mission from the configuration),
`analysis` (errors, effort, the metrics, the error metric), `figures` (matplotlib), `page` (the
table, the section and the registrations). This package imports `page` alone, so that the
reporter's discovery (bus/discovery.py `import_role("report")`) registers the section.
"""
from swarmhil.missions.p004_lbdnn.report import page  # noqa: F401 - registers the section and its error metric (discovery imports this package)
