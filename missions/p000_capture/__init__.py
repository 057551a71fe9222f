"""Paper 000's room: swarm capture of a tumbling ellipsoidal target (docs/paper000.md).

`contract`: what the plant's sensing kind `p000-landmarks` (plant/sensing/p000.py) and the flight
software (agent/missions/p000_capture/) share. Imports nothing (missions/__init__.py).
"""
