"""Paper 003 (Wei et al., Sensors 2025, 25, 5606): a leader and six servicers surround a huge
escaping target with relative sensors only.

Frame: everything is in the leader's LVLH (x radial outward, y along-track, z orbit normal).
The parameter models (§5 values and open choices), the structure (Table 1-2 ACSB spheres and slots)
and the funnel geometry are the room's contract (missions/p003_surround/contract.py). Modules:
`funnel` (eq. 16-17, TT control), `threat` (eq. 7-8), `nash` (eq. 12, 18-21), `relative_dynamics` (u_id),
`sensing` (obs.extra keys), `packets` (link payloads), `controllers` (the registered controllers).
"""
from swarmhil.missions.p003_surround.fsw import controllers  # noqa: F401  (registers p003-leader/servicer)
