"""The paper-001 controller: u = g + l + d, saturated by norm (sec. II, Table 3), registered as "p001-lattice".

Inputs and outputs are SI; the TB term is evaluated in this room's normalised units
(distances / l) and scaled back by eq. 14.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, Observation, OrbitInfo, register
from swarmhil.missions.p001_lattice.fsw.cw import far_accel
from swarmhil.missions.p001_lattice.fsw.layers import Layer, next_layer
from swarmhil.missions.p001_lattice.contract import CONTROLLER, TB_GAIN, LatticeParams, hexagon_vertices
from swarmhil.missions.p001_lattice.fsw.sensing import OwnState
from swarmhil.missions.p001_lattice.fsw.tersoff import forces, tersoff_params
from swarmhil.missions.p001_lattice.fsw.wells import damping, planar_well, point_well, saturate


def tb_accel(rel_position_m: np.ndarray, side_m: float, tb, accel_unit_mps2: float) -> np.ndarray:
    """Eq. 14: l_i = (epsilon/m_carbon) F_i, F_i = -dE/dx_i of the cluster {i} + sensed neighbours, m/s^2."""
    rel = np.asarray(rel_position_m, dtype=float).reshape(-1, 3)
    if rel.shape[0] == 0:
        return np.zeros(3)
    cluster = np.vstack([np.zeros((1, 3)), rel / side_m])
    return TB_GAIN * accel_unit_mps2 * forces(cluster, tb)[0]


class LatticeController:
    """One spacecraft's flight software for paper 001 (far / near / shaping layers, latched)."""

    name = CONTROLLER

    def __init__(self, params: LatticeParams) -> None:
        self.p = params
        self.tb = tersoff_params(params.cutoff_reading)
        self.layer = Layer.FAR
        self.dock_m = hexagon_vertices(params.side_m, params.phase_deg, params.x_shift_m)[0]
        self.centre_m = np.array([params.x_shift_m, 0.0, 0.0])

    def gathering(self, own: OwnState, t_s: float) -> np.ndarray:
        """g of the current layer (Table 3), m/s^2."""
        p, r, v = self.p, own.position_m, own.velocity_mps
        if self.layer == Layer.FAR:
            g = far_accel(r, v, p.mean_motion_radps, p.t_desire_s - t_s, p.far_gain_ps)
            return g + damping(v, p.damping_ps) if p.far_damping else g
        if self.layer == Layer.NEAR:
            return point_well(r, self.centre_m, p.alpha_free_ps2, p.k_free_m2) + damping(v, p.damping_ps)
        g = planar_well(r, p.x_shift_m, p.alpha_planar_ps2, p.k_planar_m2)
        g = g + point_well(r, self.dock_m, p.alpha_phase_ps2, p.k_phase_m2)
        if p.free_in_shaping:
            g = g + point_well(r, self.centre_m, p.alpha_free_ps2, p.k_free_m2)
        return g + damping(v, p.damping_ps)

    def step(self, obs: Observation) -> Command:
        own = OwnState.from_extra(obs.extra)
        p = self.p
        self.layer = next_layer(self.layer, float(np.linalg.norm(own.position_m)), obs.t_s,
                                p.r_middle_m, p.r_inner_m, p.t_natural_s)
        u = self.gathering(own, obs.t_s) + tb_accel(obs.rel_position_m, p.side_m, self.tb, p.tb_accel_unit_mps2)
        return Command(accel_mps2=saturate(u, p.max_accel_mps2), mode=self.layer.name.lower())


def _check(params: dict[str, Any]) -> None:
    """Scenario-load check of [controller.params] (unknown keys and bad values are errors)."""
    LatticeParams.from_dict({"mean_motion_radps": 7.2921e-5, **params})


@register(CONTROLLER, validate=_check)
def _p001_lattice(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> LatticeController:
    merged = {"mean_motion_radps": orbit.mean_motion_radps, **params}
    return LatticeController(LatticeParams.from_dict(merged))
