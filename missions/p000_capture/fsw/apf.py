"""Repulsion: inter-agent APF (paper 000 eq. 11–13, n = 1) and the target buffer (§2.3.2)."""
from __future__ import annotations

import numpy as np

from swarmhil.missions.p000_capture.contract import dot3


def apf_potential(d_m: float, k_r: float, r_h_m: float) -> float:
    """U = ½ k_r (1/d − 1/R_h)² for d ≤ R_h, else 0 (eq. 11 with n = 1, NOTES-000)."""
    return 0.5 * k_r * (1.0 / d_m - 1.0 / r_h_m) ** 2 if d_m <= r_h_m else 0.0


def apf_force(rel_m: np.ndarray, k_r: float, r_h_m: float) -> np.ndarray:
    """F_col = Σ_j k_r (1/d − 1/R_h)(r_i − r_j)/d³ over d ≤ R_h (eq. 12–13, n = 1), newtons.

    `rel_m` is (N, 3) of r_j − r_i (the Observation's neighbour rows).
    """
    rel = np.asarray(rel_m, dtype=float).reshape(-1, 3)
    if len(rel) == 0:
        return np.zeros(3)
    d = np.linalg.norm(rel, axis=1)
    near = (d <= r_h_m) & (d > 0.0)
    dn = d[near]
    coef = k_r * (1.0 / dn - 1.0 / r_h_m) / dn ** 3
    return -(coef[:, None] * rel[near]).sum(axis=0)


def apf_forces(rel_m: np.ndarray, offsets: np.ndarray, k_r: float, r_h_m: float) -> np.ndarray:
    """`apf_force` of N agents at once: agent i's neighbour rows are rel_m[offsets[i]:offsets[i + 1]]
    (CSR, an ObservationBatch's); row i the bits of `apf_force(rel_m[a:b])`. The same elementwise
    terms over all pairs; each agent's sum adds its near pairs in their order onto 0.0, as numpy's
    sum over axis 0 of an (n, 3) array does (row after row), one neighbour slot at a time."""
    rel = np.asarray(rel_m, dtype=float).reshape(-1, 3)
    off = np.asarray(offsets, dtype=np.int64)
    n = len(off) - 1
    counts = off[1:] - off[:-1]
    d = np.linalg.norm(rel, axis=1)
    near = (d <= r_h_m) & (d > 0.0)
    dn = d[near]
    coef = k_r * (1.0 / dn - 1.0 / r_h_m) / dn ** 3
    terms = coef[:, None] * rel[near]
    owner = np.repeat(np.arange(n), counts)[near]
    # the k-th near pair of its owner: its index among the near pairs minus its owner's first one's
    first = np.zeros(n + 1, dtype=np.int64)
    np.add.accumulate(np.bincount(owner, minlength=n), out=first[1:])
    slot = np.arange(len(owner)) - first[owner]
    acc = np.zeros((n, 3))
    for k in range(int(slot.max()) + 1 if len(slot) else 0):
        at = slot == k  # (one pair per owner)
        acc[owner[at]] = acc[owner[at]] + terms[at]
    out = -acc
    out[counts == 0] = 0.0  # no neighbours at all: apf_force's np.zeros(3)
    return out


def buffer_force(signed_distance_m: float, normal: np.ndarray, rel_velocity_mps: np.ndarray,
                 k_r_target: float, r_buffer_m: float, damping_nspm: float,
                 min_distance_m: float = 0.05) -> np.ndarray:
    """Buffer repulsion off the (estimated or sensed) surface, §2.3.2 (NOTES-000 reading).

    Eq. 11's form on the signed distance s to the surface along the outward normal n:
    k_r,target (1/s − 1/R_buffer)/s² n for s < R_buffer (s floored at `min_distance_m`), plus
    damping −c (v·n) n of inward motion ("damping may be introduced", §2.3.2).
    """
    if signed_distance_m >= r_buffer_m:
        return np.zeros(3)
    s = max(signed_distance_m, min_distance_m)
    n = np.asarray(normal, dtype=float)
    f = k_r_target * (1.0 / s - 1.0 / r_buffer_m) / s ** 2 * n
    vn = dot3(rel_velocity_mps, n)
    if vn < 0.0:
        f = f - damping_nspm * vn * n
    return f
