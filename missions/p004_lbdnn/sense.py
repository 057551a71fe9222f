"""Sensing kind `p004-partial` (paper 004, eqs. 9-10): relative positions to graph neighbours and
a partial measurement of the defunct craft, in ECI axes.

For every servicer i flown by `p004-lbdnn`:

    "p004.d_m/<j>"       d_ij = q_j - q_i + noise, (3,) m, one per graph neighbour j (eq. 9)
    "p004.y_m/<defunct>" y_i = C_i (q0 - q_i) + noise, (m_i,) m, when b_i = 1 (eq. 10)

(bus/codec.py add_measurement; the agent sees them as obs.extra["<name>/<subject>"], read by
missions/p004_lbdnn/fsw/sensing.py). Positions are the plant's inertial propagator state
(`MissionWorld.eci()`), so the scenario must fly `[plant] fidelity = "inertial"`; q0 is the
`[[body]]` named by `defunct_id` (propagated).

One source of truth for the graph, C_i and b_i: the servicer's own controller parameters
(`Scenario.controller_of(id)`, parsed by `mission_from_params` of the room's contract,
missions/p004_lbdnn/contract.py, exactly as the flight software parses them; the names `KEY_D`,
`KEY_Y` and `CONTROLLER` come from there too); `[sensing.params]` holds only the sensor: the
defunct craft's id and the noise. Noise: white Gaussian, `noise_std_m` per component (paper:
sqrt(0.5) m), drawn by `measurement_noise` from a generator seeded by ([run].seed, step, spacecraft
index), so a draw does not depend on the order in which the plant asks for the stimuli. A dead
neighbour is not measured.
"""
from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import add_measurement
from swarmhil.missions.p004_lbdnn.contract import CONTROLLER, KEY_D, KEY_Y, ServicerConfig, mission_from_params
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.sensing.registry import SensingContext, register_sensing

KIND = "p004-partial"
NOISE_TAG = 0x004


class P004Params(BaseModel):
    """[sensing.params] of `p004-partial`."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    defunct_id: str = "defunct"                             # a propagated [[body]]
    noise_std_m: float = Field(math.sqrt(0.5), ge=0)        # 1 sigma per component (paper §6)


def measurement_noise(seed: int, step: int, index: int, n_neighbours: int, m_rows: int,
                      std_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The noise of servicer `index` at `step`: (n_neighbours, 3) on its d_ij, then (m_rows,) on y_i."""
    rng = np.random.default_rng([int(seed), NOISE_TAG, int(step), int(index)])
    return rng.normal(0.0, std_m, (n_neighbours, 3)), rng.normal(0.0, std_m, m_rows)


def servicer_configs(scenario: PlantConfig) -> dict[str, ServicerConfig]:
    """{id: ServicerConfig} of every spacecraft flown by p004-lbdnn, from its own controller params."""
    out = {}
    for sid in scenario.ids:
        name, params = scenario.controller_of(sid)
        if name != CONTROLLER:
            continue
        params = {k: v for k, v in params.items() if k != "weight_bytes"}
        out[sid] = mission_from_params(params).servicer(sid)
    return out


@register_sensing(KIND, validate=P004Params.model_validate)
class P004PartialKind:
    message = pb.Measurements

    def __init__(self, scenario: PlantConfig) -> None:
        self.p = P004Params.model_validate(scenario.sensing.get("params", {}))
        if scenario.fidelity != "inertial":
            raise ValueError(f"{KIND} measures in ECI axes: [plant].fidelity must be 'inertial' "
                             f"(got {scenario.fidelity!r})")
        bodies = {b.id: b for b in scenario.bodies}
        if self.p.defunct_id not in bodies or bodies[self.p.defunct_id].motion.kind != "propagated":
            raise ValueError(f"[sensing.params].defunct_id {self.p.defunct_id!r} is not a propagated [[body]]; "
                             f"known: {sorted(bodies)}")
        self.cfgs = servicer_configs(scenario)
        for sid, cfg in self.cfgs.items():
            missing = [j for j in cfg.neighbours if j not in scenario.ids]
            if missing:
                raise ValueError(f"{KIND}: {sid}'s graph neighbours {missing} are not spacecraft")
        self.seed = int(scenario.seed)

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.Measurements:
        msg = pb.Measurements(header=hdr, u_rad=ctx.u_rad)
        sid = ctx.ids[j]
        cfg = self.cfgs.get(sid)
        if cfg is None:
            return msg
        ids, r, _v = ctx.cached("p004.eci", ctx.world.eci)
        row = {k: n for n, k in enumerate(ids)}
        alive = {s: bool(a) for s, a in zip(ctx.ids, ctx.alive)}
        q_i = r[row[sid]]
        d_noise, y_noise = measurement_noise(self.seed, ctx.step, j, len(cfg.neighbours),
                                             cfg.c_matrix.shape[0], self.p.noise_std_m)
        for k, nb in enumerate(cfg.neighbours):
            if alive.get(nb, False):
                add_measurement(msg, KEY_D, r[row[nb]] - q_i + d_noise[k], nb)
        if cfg.b:
            y = cfg.c_matrix @ (r[row[self.p.defunct_id]] - q_i) + y_noise
            add_measurement(msg, KEY_Y, y, self.p.defunct_id)
        return msg
