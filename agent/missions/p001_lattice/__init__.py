"""Paper 001: pattern formation with the Tersoff-Brenner potential field (flight software room).

Modules: `units` (Table 1), `params` (Tables 2-4 in SI, open readings), `tersoff` (eq. 6-13),
`cw` (far layer, eq. 1-2), `wells` (eq. 3-5, 15, saturation), `layers` (Table 3 latching),
`sensing` (own state in Observation.extra), `geometry` (eq. 16, hexagon test), `controller`.
"""
from agent.missions.p001_lattice import controller  # noqa: F401,E402  (registers "p001-lattice")
