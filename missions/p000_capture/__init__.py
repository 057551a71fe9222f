"""Paper 000's room: swarm capture of a tumbling ellipsoidal target (docs/paper000.md).

`contract`: what the plant's sensing kind `p000-landmarks` (missions/p000_capture/sense.py) and the flight
software (missions/p000_capture/fsw/) share. Imports nothing (missions/__init__.py).
"""
