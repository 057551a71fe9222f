"""Paper 001's room: pattern formation with the Tersoff-Brenner potential field (docs/paper001.md).

`contract` (the controller name, units, parameter model, formation measures), `fsw/` (the flight
software), `report` (the report section). No sensing kind of its own (the plant's built-in
`relative`). Imports nothing (missions/__init__.py).
"""
