"""Sensing kind `p003-relative` (paper 003, Assumption 1: relative sensors only).

- the leader measures the target (a `[[body]]`) relative to itself: q_TL = r_T - r_L and its
  rotating-frame derivative, in the leader's LVLH;
- every other spacecraft (a servicer) measures itself relative to the leader: q_Li = r_i - r_L
  and its derivative, in the leader's LVLH.

The scenario frame must be the leader's LVLH (`[plant] frame_origin = "<leader_id>"`), so each
measurement is a difference of two truth rows. Measurements (bus/codec.py add_measurement), names
in missions/p003_surround/contract.py:

    leader:    "p003.target_rel.position_m", "p003.target_rel.velocity_mps"  (subject: target id)
    servicer:  "p003.leader_rel.position_m", "p003.leader_rel.velocity_mps"  (subject: leader id)

The agent sees them as obs.extra["<name>/<subject>"]. Optional white Gaussian noise (1 sigma per
axis), seeded by [run].seed; a target beyond `range_m` is not measured (the item is left out).
"""
from __future__ import annotations


import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import add_measurement
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.sensing.builtin import RelBatch
from swarmhil.missions.p003_surround.contract import LEADER_REL_KEY, TARGET_REL_KEY
from swarmhil.plant.sensing.registry import SensingContext, register_sensing


class P003Params(BaseModel):
    """[sensing.params] of `p003-relative`."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    leader_id: str = "lsat"                     # a [[spacecraft]] id; must be [plant].frame_origin
    target_id: str = "tsat"                     # a [[body]] id
    range_m: float = Field(1e9, gt=0)           # the leader's sensor range to the target
    position_noise_m: float = Field(0.0, ge=0)  # 1 sigma per axis
    velocity_noise_mps: float = Field(0.0, ge=0)


@register_sensing("p003-relative", validate=P003Params.model_validate)
class P003RelativeKind:
    message = pb.Measurements

    def __init__(self, scenario: PlantConfig) -> None:
        self.p = P003Params.model_validate(scenario.sensing.get("params", {}))
        if self.p.leader_id not in scenario.ids:
            raise ValueError(f"[sensing.params].leader_id {self.p.leader_id!r} is not a spacecraft; "
                             f"known: {list(scenario.ids)}")
        if self.p.target_id not in [b.id for b in scenario.bodies]:
            raise ValueError(f"[sensing.params].target_id {self.p.target_id!r} is not a [[body]]; "
                             f"known: {[b.id for b in scenario.bodies]}")
        origin = scenario.plant_options.get("frame_origin", "reference")
        if origin != self.p.leader_id:
            raise ValueError(f"p003-relative measures in the leader's LVLH: [plant].frame_origin must be "
                             f"{self.p.leader_id!r} (got {origin!r})")
        self.leader = list(scenario.ids).index(self.p.leader_id)
        self._servicer_keys = (f"{LEADER_REL_KEY}.position_m/{self.p.leader_id}", f"{LEADER_REL_KEY}.velocity_mps/{self.p.leader_id}")
        self.rng = np.random.default_rng([int(scenario.seed), 0x003])
        if not (self.p.position_noise_m or self.p.velocity_noise_mps):
            self.batch = self.batch_noise_free  # the batch mode's arrays (issue 29); noisy: the messages, in order

    def _noisy(self, rp: np.ndarray, rv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.p.position_noise_m:
            rp = rp + self.rng.normal(0.0, self.p.position_noise_m, 3)
        if self.p.velocity_noise_mps:
            rv = rv + self.rng.normal(0.0, self.p.velocity_noise_mps, 3)
        return rp, rv

    def measured(self, ctx: SensingContext, j: int) -> list[tuple[str, str, np.ndarray]]:
        """Spacecraft j's measurements at this step, (name, subject, values), noise drawn in order."""
        pos, vel, lead = ctx.position_m, ctx.velocity_mps, self.leader
        if j == lead:
            target = ctx.cached("p003.target", lambda: next(
                b for b in ctx.world.body_truth() if b.spec.id == self.p.target_id))
            rp, rv = target.position_m - pos[lead], target.velocity_mps - vel[lead]
            if not np.linalg.norm(rp) <= self.p.range_m:
                return []
            rp, rv = self._noisy(rp, rv)
            return [(f"{TARGET_REL_KEY}.position_m", self.p.target_id, rp),
                    (f"{TARGET_REL_KEY}.velocity_mps", self.p.target_id, rv)]
        rp, rv = self._noisy(pos[j] - pos[lead], vel[j] - vel[lead])
        return [(f"{LEADER_REL_KEY}.position_m", self.p.leader_id, rp),
                (f"{LEADER_REL_KEY}.velocity_mps", self.p.leader_id, rv)]

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.Measurements:
        msg = pb.Measurements(header=hdr, u_rad=ctx.u_rad)
        for name, subject, values in self.measured(ctx, j):
            add_measurement(msg, name, values, subject)
        return msg

    def batch_noise_free(self, ctx: SensingContext, observers: np.ndarray) -> RelBatch:
        """What `stimulus` gives each of `observers` as arrays, without noise (the batch mode, issue 29):
        the measurements as the named arrays `extra` holds (`name/subject`, the messages' float64 values);
        the servicers' q_Li and q'_Li as rows of one difference of the truth arrays (elementwise: the
        values of `measured`'s)."""
        lead, (pos_key, vel_key) = self.leader, self._servicer_keys
        rel_p, rel_v = ctx.position_m - ctx.position_m[lead], ctx.velocity_mps - ctx.velocity_mps[lead]
        return RelBatch.named([{f"{name}/{subject}": values for name, subject, values in self.measured(ctx, j)} if j == lead
                               else {pos_key: rel_p[j], vel_key: rel_v[j]} for j in np.asarray(observers).tolist()])
