"""Navigation error against truth, from the recording alone (issue 4), and a comparison of runs.

What an agent believed is in its telemetry (MCAP topic `sc/<id>/tm`, `swarm/<run>/sc/<id>/tm` in
recordings made before the MCAP contract; DESIGN.md): each
`TrackEstimate` holds the estimated state of a neighbour k relative to the observer j (k minus j):
LVLH position and velocity and ROE in metres, a*(da, dl, dex, dey, dix, diy), with the 6x6 ROE
covariance where the estimator has one (agent/nav/base.py). What was true is the `Truth` of the
same step (the scene stimulus of step k is imaged from the truth of step k; dashboards/truth_io.py).

- Association: each track row is paired with the spacecraft k != j whose true relative position
  r_k - r_j is nearest to the track's estimated relative position (Euclidean, metres). The
  distance to the second nearest is kept: a row whose two candidates are about as near is
  ambiguous. A track whose associated spacecraft changes during its life has an identity switch.
- Errors: position e_r = r_hat - (r_k - r_j), velocity likewise, ROE e = roe_hat - (roe_k - roe_j);
  NEES = e^T P^-1 e (6 degrees of freedom; mean 6 for a consistent filter, Bar-Shalom et al.,
  "Estimation with Applications to Tracking and Navigation", sec. 5.4).
- What the controller acted on: the behaviour decisions in the same telemetry name the neighbour
  (a track id, or with ideal `rel` sensing the true id) and carry the ROE of the observer relative
  to the neighbour it used, roe_jk = -(roe_k - roe_j) (NOTES-002); its error against truth is the
  "decision ROE error". With ideal sensing it is zero.
- Coverage: the fraction of truly visible pairs (plant rule, plant/sensors.visibility_matrix) that
  have a track associated with them at that step.

- Splits and per-step comparisons (issue 36, `diagnosis`): each split of the visibility digraph
  (1 weakly connected component -> more) with the edges lost and what both ends' navigation believed
  about each over the steps before; per step, the visible pairs without a track (missed, lost), false
  tracks, swaps, breaks and duplicates, and the errors of each layer (tracks, tracks used, decisions).

`write_nav_report(run_dir)` writes run_dir/navreport/{index.html, nav_summary.json, nav_table.md,
nav_splits.json, nav_splits.md, nav_steps.json, *.png}; `write_comparison(run_dirs, out_dir)` the
table across runs (total dV, weak connectivity, separations, closest approach, navigation error) as
Markdown, JSON and HTML.

The package is split by job, each module importing only the ones before it: `read` (tracks and decisions from telemetry) <- `analysis` (association, errors, summary) <- `diagnosis` (splits, per-step comparisons) <- `figures` <- `page` (navreport/ and the comparison of runs).
"""
