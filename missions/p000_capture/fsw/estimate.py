"""The agent's target estimate: direct GNC fits, velocity by an α-β filter, consensus (eq. 30)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.missions.p000_capture.contract import Ellipsoid


@dataclass
class TargetEstimate:
    t_s: float
    centre_m: np.ndarray
    velocity_mps: np.ndarray
    shape: np.ndarray          # M = R diag(a⁻²) Rᵀ
    direct: bool               # from this agent's own fit (not only relayed)

    def ellipsoid(self, t_s: float) -> Ellipsoid:
        """The estimate propagated to t with the estimated velocity."""
        return Ellipsoid.from_shape_matrix(self.centre_m + self.velocity_mps * (t_s - self.t_s), self.shape)

    def semi_axes_sorted(self) -> np.ndarray:
        return np.sort(Ellipsoid.from_shape_matrix(self.centre_m, self.shape).semi_axes_m)


def alpha_beta(prev: TargetEstimate | None, t_s: float, centre_m: np.ndarray,
               alpha: float = 0.5, beta: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Centre and velocity after a new centroid measurement (α-β filter)."""
    if prev is None:
        return np.asarray(centre_m, dtype=float), np.zeros(3)
    dt = t_s - prev.t_s
    pred = prev.centre_m + prev.velocity_mps * dt
    res = centre_m - pred
    c = pred + alpha * res
    v = prev.velocity_mps + (beta / dt) * res if dt > 0 else prev.velocity_mps
    return c, v


def consensus(own: TargetEstimate | None, others: list[TargetEstimate], t_s: float,
              own_weight: float) -> TargetEstimate | None:
    """x̂_i = Σ w_ij x̂_j (eq. 30) over centre, velocity and the shape matrix M (NOTES-000: fuse M,
    not axes); estimates are propagated to t first; the own estimate weighs `own_weight` when it
    is a direct fit (trap 7: stale relayed estimates), the rest share the remainder equally."""
    fused = Consensus.of(own, others, own_weight)
    return None if fused is None else fused.at(t_s)


class Consensus:
    """`consensus` of one list of estimates at any time: the weights, the fused velocity and shape
    matrix (which do not depend on t) computed once, the centre at each `at(t_s)` (a flight
    software's estimates change at fits and received broadcasts, its consensus every step)."""

    def __init__(self, own: TargetEstimate | None, others: list[TargetEstimate], own_weight: float) -> None:
        ests = ([own] if own is not None else []) + others
        if own is not None and own.direct and others:
            w = np.array([own_weight] + [(1.0 - own_weight) / len(others)] * len(others))
        else:
            w = np.full(len(ests), 1.0 / len(ests))
        self.own, self.others, self.own_weight = own, list(others), own_weight
        self.w_col = w[:, None]
        self.vel = np.array([e.velocity_mps for e in ests])
        self.t_est = np.array([e.t_s for e in ests])
        self.centres = np.array([e.centre_m for e in ests])
        # sums over the estimates, in their order (a reduction over axis 0 adds row after row)
        self.v = (self.w_col * self.vel).sum(axis=0)
        self.m = (w[:, None, None] * np.array([e.shape for e in ests])).sum(axis=0)
        self.direct = own is not None and own.direct

    @classmethod
    def of(cls, own: TargetEstimate | None, others: list[TargetEstimate], own_weight: float) -> "Consensus | None":
        """None without any estimate."""
        return cls(own, others, own_weight) if own is not None or others else None

    def holds(self, own: TargetEstimate | None, others: list[TargetEstimate], own_weight: float) -> bool:
        """Whether this is the consensus of these very estimates (the same objects, in order)."""
        return (self.own is own and own_weight == self.own_weight and len(others) == len(self.others)
                and all(a is b for a, b in zip(others, self.others)))

    def at(self, t_s: float) -> TargetEstimate:
        """The fused estimate at t_s (its velocity and shape matrix copies of the fused ones)."""
        ages = t_s - self.t_est
        c = (self.w_col * (self.centres + self.vel * ages[:, None])).sum(axis=0)
        return TargetEstimate(t_s, c, self.v.copy(), self.m.copy(), self.direct)
