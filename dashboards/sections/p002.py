"""Paper 002's report section is its room's: missions/p002_sabatini/report.py (issue 25). The
sections' discovery imports every module of this package; this one imports the room's report, which
registers the section `p002-swarm`, until the discovery looks in every room (docs/architecture.md
"Mission rooms", later step (1))."""
from missions.p002_sabatini import report as _report  # noqa: F401  (registers "p002-swarm")
