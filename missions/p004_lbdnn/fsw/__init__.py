"""Paper 004: collaborative servicing under partial feedback with a Lyapunov-based DNN.

Modules: lbdnn (network and Jacobian, eqs. 2-3), rho_filter (eq. 25), observer (eqs. 12, 26),
control_law (eq. 27), adaptation (eq. 28), sensing (reading obs.extra), packet (link payload),
controller (registered as "p004-lbdnn").
The gains, C_i, b_i, the graph (H of eq. 29) and the measurement names are the room's contract,
shared with the plant's sensing kind: missions/p004_lbdnn/contract.py. Importing the package
registers the controller.
"""
from swarmhil.missions.p004_lbdnn.fsw import controller as _controller  # noqa: F401  (registers "p004-lbdnn")
