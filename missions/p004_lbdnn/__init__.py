"""Paper 004's room: collaborative servicing under partial feedback (docs/paper004.md).

`contract`: what the plant's sensing kind `p004-partial` (plant/sensing/p004.py) and the flight
software (agent/missions/p004_lbdnn/) share. Imports nothing (missions/__init__.py).
"""
