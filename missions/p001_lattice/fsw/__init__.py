"""Paper 001: pattern formation with the Tersoff-Brenner potential field (flight software room).

The units (Table 1), the parameter model (Tables 2-4 in SI, open readings) and the formation
measures (eq. 16, hexagon test) are the room's contract (missions/p001_lattice/contract.py). Modules:
`tersoff` (eq. 6-13), `cw` (far layer, eq. 1-2), `wells` (eq. 3-5, 15, saturation), `layers`
(Table 3 latching), `sensing` (own state in Observation.extra), `controller`.
"""
from swarmhil.missions.p001_lattice.fsw import controller  # noqa: F401,E402  (registers "p001-lattice")
