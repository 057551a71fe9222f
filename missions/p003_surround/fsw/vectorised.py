"""Paper 003's Nash CT terms for S servicers at once, each over its own view of the swarm (issue 29).

Servicer s keeps its own x~ and ξ (N, 6) (its own row fresh, the others as last received) and its
own sphere centres q_Cg (G, 3) (the leader's packet carried forward), so the inputs here are
stacked (S, N, 6) and (S, G, 3). The equations are nash.py's and threat.py's (eqs. 7, 8, 12, 18-21)
with every sum an elementwise product summed along a fixed axis (no einsum or BLAS call whose
loop may depend on S): servicer s's numbers do not depend on how many share the call, so
`ServicerController.step` (S = 1) and `step_batch` (S = 6) give the same bits
(tests/test_batch_missions.py).
"""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p003_surround.contract import GameParams


def _gap(d: np.ndarray, radius_m: np.ndarray | float, floor_m2: float) -> tuple[np.ndarray, np.ndarray]:
    """|d|^2 - R^2 floored at floor_m2, and where it is above the floor (threat.py `_gap_m2`)."""
    raw = (d * d).sum(axis=-1) - np.asarray(radius_m) ** 2
    return np.maximum(raw, floor_m2), raw > floor_m2


def grad_and_xi_rate(x_err: np.ndarray, xi: np.ndarray, slots_m: np.ndarray, centres_m: np.ndarray,
                     radii_m: np.ndarray, own: np.ndarray, g: GameParams) -> tuple[np.ndarray, np.ndarray]:
    """For each servicer s, row own[s] of nash.value_grad_x (∂V_i/∂x~_i, eq. 18) and of nash.xi_rate
    (ξ', eq. 20) over its view (x_err[s], xi[s], centres_m[s]): two (S, 6) arrays."""
    n = x_err.shape[1]
    pos = xi[:, :, :3] + slots_m                                     # (S, N, 3)
    d = pos[:, :, None, :] - pos[:, None, :, :]                      # (S, N, N, 3) q_Li - q_Lj
    gap, live = _gap(d, 2.0 * g.safe_radius_m, g.barrier_floor_m2)  # every servicer's safe radius
    idx = np.arange(n)
    phi = gap ** (-g.h_fc)
    phi[:, idx, idx] = 0.0
    dc = pos[:, :, None, :] - centres_m[:, None, :, :]               # (S, N, G, 3)
    gap_c, live_c = _gap(dc, g.safe_radius_m + radii_m, g.barrier_floor_m2)
    th = g.kappa + g.alpha_fc * phi.sum(axis=-1) + g.alpha_cg * (gap_c ** (-g.h_cg)).sum(axis=-1)  # eq. 19
    grad_x = (th + g.gamma)[:, :, None] * x_err + g.r_weight * (x_err - xi)
    # ξ' = -η ∂(Σ_k V_k)/∂ξ (nash.py `xi_rate`)
    w = 0.5 * (x_err * x_err).sum(axis=-1)                           # (S, N)
    pair = np.where(live, -2.0 * g.h_fc * gap ** (-(g.h_fc + 1.0)), 0.0)[..., None] * d
    pair[:, idx, idx, :] = 0.0
    struct = (np.where(live_c, -2.0 * g.h_cg * gap_c ** (-(g.h_cg + 1.0)), 0.0)[..., None] * dc).sum(axis=-2)
    grad = -g.r_weight * (x_err - xi)
    grad[:, :, :3] += g.alpha_fc * ((w[:, :, None] + w[:, None, :])[..., None] * pair).sum(axis=2)
    grad[:, :, :3] += g.alpha_cg * w[:, :, None] * struct
    rate = -g.eta * grad
    rows = np.arange(len(own))
    return grad_x[rows, own], rate[rows, own]
