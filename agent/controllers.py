"""Built-in controllers, registered by name for scenarios (`[controller] name = ...`): `null` and
`drift-null`, the baselines any run may fly (paper 002's uncontrolled swarm, the demo, hil-3).
Paper 002's behavioural law `sabatini` is its room's flight software (missions/p002_sabatini/fsw/),
loaded by agent/catalogue.py like every room's."""
from __future__ import annotations

from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, register


class NullController:
    """No thrust, ever: the uncontrolled swarm of paper 002 Fig. 7."""

    name = "null"
    observes = False  # the command never depends on the observation (the batch mode skips the stimuli)

    def step(self, obs: Observation) -> Command:
        return Command(accel_mps2=np.zeros(3), mode="coast")

    @classmethod
    def step_batch(cls, controllers: list["NullController"], batch: ObservationBatch) -> CommandBatch:
        """`step` of every spacecraft of a batch (agent/controller.py): zero thrust, coasting."""
        return CommandBatch(accel_mps2=np.zeros((len(controllers), 3)), modes=["coast"] * len(controllers))


class DriftNullController:
    """Along-track thrust that cancels the mean relative drift to the visible neighbours.

    The relative semi-major axis of neighbour k seen from j is a*da_kj = 4x + 2*vy/n
    (first row of M, NOTES-002). Since d(a*da)/dt = 2/n * u_y (B(u), NOTES-002), thrusting
    u_y = gain * n/2 * mean_k(a*da_kj) moves j's own semi-major axis toward its neighbours',
    removing drift with time constant 1/gain.
    """

    name = "drift-null"

    def __init__(self, orbit: OrbitInfo, gain_per_s: float, max_accel_mps2: float) -> None:
        self.n = orbit.mean_motion_radps
        self.gain = gain_per_s
        self.max_accel = max_accel_mps2

    def step(self, obs: Observation) -> Command:
        if len(obs.neighbour_ids) == 0:
            return Command(accel_mps2=np.zeros(3), mode="search")
        r, v = obs.rel_position_m, obs.rel_velocity_mps
        da_m = 4.0 * r[:, 0] + 2.0 * v[:, 1] / self.n
        uy = self.gain * self.n / 2.0 * float(np.mean(da_m))
        uy = float(np.clip(uy, -self.max_accel, self.max_accel))
        return Command(accel_mps2=np.array([0.0, uy, 0.0]), mode="drift-null")


@register("null")
def _null(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> NullController:
    return NullController()


def _check_drift_null(params: dict[str, Any]) -> None:
    unknown = sorted(set(params) - {"gain_per_s", "max_accel_mps2"})
    if unknown:
        raise ValueError(f"unknown parameter {unknown[0]!r}; known: ['gain_per_s', 'max_accel_mps2']")
    for k in ("gain_per_s", "max_accel_mps2"):  # finite numbers >= 0 (a string, a bool or NaN is refused)
        v = params.get(k, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
            raise ValueError(f"{k} must be a finite number >= 0 (got {v!r})")


@register("drift-null", validate=_check_drift_null)
def _drift_null(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> DriftNullController:
    return DriftNullController(
        orbit,
        gain_per_s=float(params.get("gain_per_s", 1e-4)),
        max_accel_mps2=float(params.get("max_accel_mps2", 1e-3)),
    )
