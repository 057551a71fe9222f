"""Paper 002's contract: the names and thresholds its flight software and its report share.

Imports nothing of the project (numpy-free too). Read by the flight software
(missions/p002_sabatini/fsw/: `CONTROLLER` is the name it registers, the thresholds are
`SabatiniParams`' defaults) and by the report (missions/p002_sabatini/report.py: which runs its
section covers, and the thresholds of its metrics: the share of steps at or beyond each). The
plant needs nothing of paper 002 but the generic `rel` / camera sensing and the ROE propagators of
plant/dynamics/. docs/architecture.md "Mission rooms (issue 25)".
"""
from __future__ import annotations

CONTROLLER = "sabatini"  # the behavioural law (sections 3.3-3.8), `[controller] name` of the scenarios

D_MIN_M = 100.0        # along-track minimum distance (section 3.2)
D_MIN_TRANS_M = 30.0   # radial / cross-track minimum distance (section 3.2)
PARALLEL_MIN = 0.8     # NotParallel when |de.di|/(|de||di|) < 0.8 (Algorithm 1)
