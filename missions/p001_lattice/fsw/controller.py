"""The paper-001 controller: u = g + l + d, saturated by norm (sec. II, Table 3), registered as "p001-lattice".

Inputs and outputs are SI; the TB term is evaluated in this room's normalised units
(distances / l) and scaled back by eq. 14.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, register
from swarmhil.missions.p001_lattice.fsw.cw import cw_position_blocks, far_accel
from swarmhil.missions.p001_lattice.fsw.layers import Layer, next_layer
from swarmhil.missions.p001_lattice.contract import CONTROLLER, TB_GAIN, LatticeParams, hexagon_vertices
from swarmhil.missions.p001_lattice.fsw.sensing import OWN_POSITION_KEY, OWN_VELOCITY_KEY, OwnState
from swarmhil.missions.p001_lattice.fsw.tersoff import forces, tersoff_params
from swarmhil.missions.p001_lattice.fsw.wells import damping, planar_well, point_well, saturate


def tb_accel(rel_position_m: np.ndarray, side_m: float, tb, accel_unit_mps2: float) -> np.ndarray:
    """Eq. 14: l_i = (epsilon/m_carbon) F_i, F_i = -dE/dx_i of the cluster {i} + sensed neighbours, m/s^2."""
    rel = np.asarray(rel_position_m, dtype=float).reshape(-1, 3)
    if rel.shape[0] == 0:
        return np.zeros(3)
    cluster = np.vstack([np.zeros((1, 3)), rel / side_m])
    return TB_GAIN * accel_unit_mps2 * forces(cluster, tb)[0]


_MODE = {layer: layer.name.lower() for layer in Layer}  # the Command's mode of each layer


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

    @classmethod
    def step_batch(cls, controllers: list["LatticeController"], batch: ObservationBatch) -> CommandBatch:
        """The step of N spacecraft (issue 29), each command bit for bit its own `step`'s: the far
        layer's ballistic systems solved in one stacked `np.linalg.solve` (LAPACK on each system
        alone, as the single call), every other norm, product and sum as `step` computes it on each
        row; the near and shaping wells and the Tersoff-Brenner term per spacecraft through the same
        functions. Controllers with different parameters step one by one."""
        p = controllers[0].p
        if any(c.p is not p and c.p != p for c in controllers):
            return CommandBatch.of([c.step(batch.observation(i)) for i, c in enumerate(controllers)])
        n, t = len(controllers), float(batch.t_s)
        extra = batch.extra if batch.extra is not None else [{}] * n
        pos, vel = np.empty((n, 3)), np.empty((n, 3))
        for r, e in enumerate(extra):  # OwnState.from_extra's values (a missing or bad one raises: each `step` then)
            pos[r], vel[r] = e[OWN_POSITION_KEY], e[OWN_VELOCITY_KEY]
        # a finite sum: every entry is finite (a sum that overflows only sends the batch to each `step`)
        if not math.isfinite(np.add.reduce(pos, axis=None) + np.add.reduce(vel, axis=None)):
            raise ValueError("non-finite own state in the batch")
        for c, pr in zip(controllers, pos):  # (pr: a view of the row)
            c.layer = next_layer(c.layer, math.sqrt(float(pr.dot(pr))), t, p.r_middle_m, p.r_inner_m,
                                 p.t_natural_s)  # float(np.linalg.norm(r)) = sqrt(r . r)
        g = np.empty((n, 3))
        far = [r for r, c in enumerate(controllers) if c.layer == Layer.FAR]
        if far:  # eq. 1-2 (cw.far_accel) for every far spacecraft at once
            if not p.t_desire_s - t > 0.0:
                raise ValueError(f"time to go {p.t_desire_s - t} s: the ballistic field is only defined before t_desire")
            phi_rr, phi_rv = cw_position_blocks(p.mean_motion_radps, p.t_desire_s - t)
            rows: slice | list[int] = slice(None) if len(far) == n else far  # (all far: no gather and scatter)
            pos_far, vel_far = pos[rows], vel[rows]
            rhs = np.matmul(phi_rr, pos_far[:, :, None])  # (k, 3, 1): phi_rr @ r of each, the same gemv as `step`'s
            systems = np.empty((len(far), 3, 3))
            systems[:] = phi_rv
            v_d = -np.linalg.solve(systems, rhs)[:, :, 0]
            g_far = p.far_gain_ps * (v_d - vel_far)
            if p.far_damping:
                g_far = g_far + damping(vel_far, p.damping_ps)
            g[rows] = g_far
        if len(far) < n:
            for r, c in enumerate(controllers):
                if c.layer != Layer.FAR:
                    g[r] = c.gathering(OwnState(pos[r], vel[r]), t)
        tb = np.zeros((n, 3))
        off = batch.offsets.tolist()
        if off[n] > 0:  # someone sees a neighbour
            for r, c in enumerate(controllers):
                if off[r + 1] > off[r]:
                    tb[r] = tb_accel(batch.rel_position_m[off[r]:off[r + 1]], p.side_m, c.tb, p.tb_accel_unit_mps2)
        u = g + tb
        for r, ur in enumerate(u):  # wells.saturate, row by row (ur: a view of row r)
            norm = math.sqrt(float(ur.dot(ur)))
            if not norm <= p.max_accel_mps2:
                u[r] = ur * (p.max_accel_mps2 / norm)
        return CommandBatch(accel_mps2=u, modes=[_MODE[c.layer] for c in controllers])


def _check(params: dict[str, Any]) -> None:
    """Scenario-load check of [controller.params] (unknown keys and bad values are errors)."""
    LatticeParams.from_dict({"mean_motion_radps": 7.2921e-5, **params})


@register(CONTROLLER, validate=_check)
def _p001_lattice(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> LatticeController:
    merged = {"mean_motion_radps": orbit.mean_motion_radps, **params}
    lp = LatticeParams.from_dict(merged)
    if len(_SHARED_PARAMS) > 1024:
        _SHARED_PARAMS.clear()
    return LatticeController(_SHARED_PARAMS.setdefault(lp, lp))


# equal parameters as one object: `step_batch` tells a batch of one set of parameters by identity
_SHARED_PARAMS: dict[LatticeParams, LatticeParams] = {}
