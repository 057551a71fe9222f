"""The paper-001 controller: u = g + l + d, saturated by norm (sec. II, Table 3), registered as "p001-lattice".

Inputs and outputs are SI; the TB term is evaluated in this room's normalised units
(distances / l) and scaled back by eq. 14.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, register
from swarmhil.agent.rowwise import row_dots
from swarmhil.missions.p001_lattice.fsw.cw import cw_position_blocks, far_accel, matvec_rows, solve_each
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
        layer's ballistic systems solved in one stacked LAPACK call (`cw.solve_each`: `dgesv` on
        each system alone, as the single call), each norm the BLAS `ddot` of its row (`row_dots`:
        what `np.linalg.norm` of the row computes) and every other product and sum as `step`
        computes it on each row; the near and shaping wells and the Tersoff-Brenner term per
        spacecraft through the same functions. Controllers with different parameters step one by one."""
        p = controllers[0].p
        params = [c.p for c in controllers]
        if params.count(p) != len(params):  # (list.count: identity first, then ==)
            return CommandBatch.of([c.step(batch.observation(i)) for i, c in enumerate(controllers)])
        n, t = len(controllers), float(batch.t_s)
        pos, vel = own_state_rows(batch.extra, n)
        radius = np.sqrt(row_dots(pos)).tolist()  # float(np.linalg.norm(r)) of each row
        lowest = min(radius)
        if not (lowest >= p.r_middle_m and lowest >= p.r_inner_m and t <= p.t_natural_s):  # else nobody moves in
            # a layer may move: only for a finite own state (`step` raises before its layer test; a
            # finite sum means every entry is finite, one that overflows only sends the batch to each
            # `step`). Without the test a non-finite own state makes that spacecraft's command
            # non-finite in every layer (the far field, the wells and the damping read r and v):
            # the test of the commands below sends the batch to each `step`, no layer moved
            if not math.isfinite(np.add.reduce(pos, axis=None) + np.add.reduce(vel, axis=None)):
                raise ValueError("non-finite own state in the batch")
            for c, r in zip(controllers, radius):
                c.layer = next_layer(c.layer, r, t, p.r_middle_m, p.r_inner_m, p.t_natural_s)
        far = [r for r, c in enumerate(controllers) if c.layer == Layer.FAR]
        g_far = None
        if far:  # eq. 1-2 (cw.far_accel) for every far spacecraft at once
            if not p.t_desire_s - t > 0.0:
                raise ValueError(f"time to go {p.t_desire_s - t} s: the ballistic field is only defined before t_desire")
            phi_rr, phi_rv = cw_position_blocks(p.mean_motion_radps, p.t_desire_s - t)
            rows: slice | list[int] = slice(None) if len(far) == n else far  # (all far: no gather)
            pos_far, vel_far = pos[rows], vel[rows]
            rhs = matvec_rows(phi_rr, pos_far)  # phi_rr @ r of each, the same gemv as `step`'s
            v_d = -solve_each(phi_rv, rhs)
            g_far = p.far_gain_ps * (v_d - vel_far)
            if p.far_damping:
                g_far = g_far + damping(vel_far, p.damping_ps)
        if g_far is not None and len(far) == n:
            g = g_far  # (all far: no scatter)
        else:
            g = np.empty((n, 3))
            if g_far is not None:
                g[far] = g_far
            for r, c in enumerate(controllers):
                if c.layer != Layer.FAR:
                    g[r] = c.gathering(OwnState(pos[r], vel[r]), t)
        if len(batch.rel_position_m):  # someone sees a neighbour (offsets[n] rows)
            off = batch.offsets.tolist()
            tb = np.zeros((n, 3))
            for r, c in enumerate(controllers):
                if off[r + 1] > off[r]:
                    tb[r] = tb_accel(batch.rel_position_m[off[r]:off[r + 1]], p.side_m, c.tb, p.tb_accel_unit_mps2)
            u = g + tb
        else:
            u = g + 0.0  # (g + a row of zeros, as `step` adds tb_accel's zeros: -0.0 -> 0.0)
        norm = np.sqrt(row_dots(u))  # wells.saturate of each row: float(np.linalg.norm(u))
        if not math.isfinite(np.add.reduce(norm)):  # (a non-finite own state, a singular far system, an overflow)
            raise ValueError("non-finite command in the batch")  # each `step` then
        over = norm > p.max_accel_mps2
        if np.count_nonzero(over):
            u[over] *= (p.max_accel_mps2 / norm[over])[:, None]  # u * (u_max / |u|), row by row
        # finite: each norm is, so each entry is (and u_max / |u| of a finite |u| > u_max)
        return CommandBatch(accel_mps2=u, modes=[_MODE[c.layer] for c in controllers], finite=True)


def own_state_rows(extra: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The (n, 3) own positions and velocities of a batch's `extra`: the sensing's arrays as they
    are (`NamedRows` of float64 (n, 3) arrays), else read from each observer's dict as
    `OwnState.from_extra` reads it (a missing or malformed entry raises: each `step` then)."""
    arrays = getattr(extra, "rows", None)  # (bus/codec.py NamedRows: the batch sensing's arrays)
    if isinstance(arrays, dict):
        pos, vel = arrays.get(OWN_POSITION_KEY), arrays.get(OWN_VELOCITY_KEY)
        if (isinstance(pos, np.ndarray) and isinstance(vel, np.ndarray) and pos.shape == vel.shape == (n, 3)
                and pos.dtype == vel.dtype == np.float64 and pos.flags.c_contiguous and vel.flags.c_contiguous):
            return pos, vel
    rows = extra if extra is not None else [{}] * n
    pos, vel = np.empty((n, 3)), np.empty((n, 3))
    for r, e in enumerate(rows):
        pos[r], vel[r] = e[OWN_POSITION_KEY], e[OWN_VELOCITY_KEY]
    return pos, vel


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
