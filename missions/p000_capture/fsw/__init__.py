"""Paper 000: event-triggered swarm capture of a tumbling ellipsoidal target (Zhang, Zhu, Zhang 2026).

Pure functions over numpy arrays, one module per subject; `controller.py` registers the
"p000-capture" controller. Never imports plant/ or bus/.
"""
from . import controller  # noqa: F401  (registers "p000-capture")
