"""Built-in sensing kinds.

- `rel` (paper 002, issue 2): ideal (or ROE-noised) relative LVLH states of the spacecraft the
  observer's camera could see (plant/sensors.py visible_pairs: the visibility rule's pairs, by a
  spatial index in large swarms).
- `scene` (paper 002, issue 4): camera-frame poses of nearby bodies (plant/scene_stimulus.py).
- `relative` (issue 11): relative position and velocity of every spacecraft within a sensing ball
  (`range_m`), optionally with the observer's own state in the scenario frame (a GNSS-like absolute
  navigation differenced with the reference point), and white Gaussian noise (seeded).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import NamedRows, add_measurement
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.dynamics.limits import row_norm
from swarmhil.plant.dynamics.roe_linear import lvlh_to_roe, roe_to_lvlh
from swarmhil.plant.sensing.registry import SensingContext, register_sensing
from swarmhil.plant.sensors import CameraGeometry, visible_pairs

if TYPE_CHECKING:  # (annotation only: the scene model is loaded by the scene kind alone)
    from swarmhil.plant.scene_stimulus import SceneBatch


class _SensorNoise:
    """Paper 002 section 5: Gaussian noise as a fraction of each ROE component of the pair (seeded)."""

    def __init__(self, scenario: PlantConfig) -> None:
        self.frac = float(scenario.sensing["roe_noise_fraction"])
        self.n = scenario.orbit.mean_motion_radps
        self.rng = np.random.default_rng([int(scenario.seed), 0x5E45])

    def apply(self, rp: np.ndarray, rv: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
        roe = lvlh_to_roe(rp[None], rv[None], u, self.n)[0]
        roe = roe * (1.0 + self.frac * self.rng.standard_normal(6))
        p, v = roe_to_lvlh(roe[None], u, self.n)
        return p[0], v[0]

    def apply_rows(self, rp: np.ndarray, rv: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
        """`apply` of P pairs in order, (P, 3) each: the same draws (6 per pair, in order) and values."""
        roe = lvlh_to_roe(rp, rv, u, self.n)
        roe = roe * (1.0 + self.frac * self.rng.standard_normal((len(rp), 6)))
        return roe_to_lvlh(roe, u, self.n)


@register_sensing("rel")
class RelKind:
    message = pb.RelStimulus

    def __init__(self, scenario: PlantConfig) -> None:
        self.cam = CameraGeometry(**scenario.camera)
        self.noise = _SensorNoise(scenario) if scenario.sensing.get("roe_noise_fraction", 0.0) > 0 else None

    def _pairs(self, ctx: SensingContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(j, k, row) of the step, computed once: j sees k (plant/sensors.py `visible_pairs`, row-major:
        the visibility matrix's nonzero()), observer j's pairs at row[j]:row[j + 1]."""
        def make() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            j, k = visible_pairs(ctx.position_m, self.cam, ctx.alive)
            return j, k, np.searchsorted(j, np.arange(len(ctx.position_m) + 1))

        return ctx.cached("visible_pairs", make)

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.RelStimulus:
        _j, kk_all, row = self._pairs(ctx)
        pos, vel, u = ctx.position_m, ctx.velocity_mps, ctx.u_rad
        stim = pb.RelStimulus(header=hdr, u_rad=u)
        for kk in kk_all[row[j]:row[j + 1]].tolist():
            rp, rv = pos[kk] - pos[j], vel[kk] - vel[j]
            if self.noise is not None:
                rp, rv = self.noise.apply(rp, rv, u)
            nb = stim.neighbours.add(id=ctx.ids[kk])
            nb.position_m.x, nb.position_m.y, nb.position_m.z = rp.tolist()
            nb.velocity_mps.x, nb.velocity_mps.y, nb.velocity_mps.z = rv.tolist()
        return stim

    def stimuli(self, ctx: SensingContext, observers: list[int], headers: list[pb.Header]) -> list[pb.RelStimulus]:
        """`stimulus` of each of `observers` (distinct indices in increasing order, with their headers),
        built from one `batch`: the same pairs in the same order and the same values (each difference
        is the same elementwise subtraction). With noise, `stimulus` pair by pair (its draws' order)."""
        if self.noise is not None:
            return [self.stimulus(ctx, j, h) for j, h in zip(observers, headers)]
        b = self.batch(ctx, np.asarray(observers, dtype=np.int64))
        ids, u = ctx.ids, ctx.u_rad
        off, nbs = b.offsets.tolist(), b.neighbour.tolist()
        rel_p, rel_v = b.rel_position_m.tolist(), b.rel_velocity_mps.tolist()
        out = []
        for r, hdr in enumerate(headers):
            stim = pb.RelStimulus(header=hdr, u_rad=u)
            add = stim.neighbours.add
            for p in range(off[r], off[r + 1]):
                nb = add(id=ids[nbs[p]])
                q = nb.position_m
                q.x, q.y, q.z = rel_p[p]
                q = nb.velocity_mps
                q.x, q.y, q.z = rel_v[p]
            out.append(stim)
        return out

    def batch(self, ctx: SensingContext, observers: np.ndarray) -> "RelBatch":
        """What `stimulus` gives each of `observers` (distinct indices into ctx.ids, in increasing
        order), for all of them at once as arrays (the batch mode, issue 16): the same values
        (elementwise, the same pairs in the same order, the noise drawn from the same generator in
        the same order)."""
        j, kk, _row = self._pairs(ctx)
        pos, vel, u = ctx.position_m, ctx.velocity_mps, ctx.u_rad
        obs = np.asarray(observers, dtype=np.int64)
        if len(obs) == len(pos):  # every spacecraft observes (observers are distinct): every pair, in order
            jj = j
        else:  # the observers' pairs, row by row, neighbours in index order: stimulus's order
            at = np.full(len(pos), -1, dtype=np.int64)
            at[obs] = np.arange(len(obs))
            mine = at[j] >= 0
            j, kk = j[mine], kk[mine]
            jj = at[j]
        state = np.concatenate((pos, vel), axis=1)  # position and velocity differences in one gather
        d = state[kk] - state[j]
        rp, rv = d[:, :3], d[:, 3:]
        if self.noise is not None and len(kk):
            rp, rv = self.noise.apply_rows(rp, rv, u)
        offsets = np.zeros(len(obs) + 1, dtype=np.int64)
        np.add.accumulate(np.bincount(jj, minlength=len(obs)), out=offsets[1:])  # (np.cumsum)
        return RelBatch(offsets, kk, rp, rv, jj)


@dataclass(frozen=True)
class RelBatch:
    """The rel stimuli of many observers (CSR): observer r's neighbours are rows offsets[r]:offsets[r+1]."""

    offsets: np.ndarray  # (R + 1,)
    neighbour: np.ndarray  # (P,) index of each neighbour in ctx.ids
    rel_position_m: np.ndarray  # (P, 3) r_k - r_j, LVLH
    rel_velocity_mps: np.ndarray  # (P, 3)
    owner: np.ndarray | None = None  # (P,) the observer row r of each pair
    extra: Sequence[dict[str, np.ndarray]] | None = None  # per observer: its named arrays (None: none; or NamedRows)

    @classmethod
    def named(cls, extra: list[dict[str, np.ndarray]]) -> "RelBatch":
        """Observers that measure named arrays only (no neighbour rows): a `Measurements` kind's batch form."""
        n = len(extra)
        return cls(np.zeros(n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)),
                   np.zeros(0, dtype=np.int64), extra)


@register_sensing("scene")
class SceneKind:
    message = pb.SceneStimulus

    def __init__(self, scenario: PlantConfig) -> None:
        from swarmhil.plant.scene_stimulus import SceneStimulusBuilder  # scene sensing only: the scene model and scipy's Rotation

        self.builder = SceneStimulusBuilder(scenario)

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.SceneStimulus:
        return self.builder.stimulus(j, ctx.position_m, ctx.u_rad, hdr)

    def batch(self, ctx: SensingContext, observers: np.ndarray) -> "SceneBatch":
        """What `stimulus` gives each of `observers` (distinct, increasing indices), as arrays (the batch
        mode: plant/scene_stimulus.py SceneBatch), the same values and the same draws in the same order."""
        return self.builder.batch(observers, ctx.position_m)


class RelativeParams(BaseModel):
    """[sensing.params] of the `relative` kind."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    range_m: float = Field(1e9, gt=0)           # sensing ball radius
    position_noise_m: float = Field(0.0, ge=0)  # 1-sigma per axis
    velocity_noise_mps: float = Field(0.0, ge=0)
    own_state: bool = False                     # also the observer's own state in the scenario frame
    own_position_noise_m: float = Field(0.0, ge=0)
    own_velocity_noise_mps: float = Field(0.0, ge=0)


@register_sensing("relative", validate=RelativeParams.model_validate)
class RelativeKind:
    """Measurements: neighbours within range_m (relative LVLH states), `own_position_m` and
    `own_velocity_mps` when own_state."""

    message = pb.Measurements

    def __init__(self, scenario: PlantConfig) -> None:
        self.p = RelativeParams.model_validate(scenario.sensing.get("params", {}))
        self.rng = np.random.default_rng([int(scenario.seed), 0x4E1A])
        p = self.p
        if not (p.position_noise_m or p.velocity_noise_mps or p.own_position_noise_m or p.own_velocity_noise_mps):
            self.batch = self.batch_noise_free  # the batch mode's arrays (issue 29); noisy: the messages
        self._no_pairs: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def _none_in_range(self, observers: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(offsets, pair indices, pair rows) of `observers` observers without a neighbour, read-only."""
        out = (np.zeros(observers + 1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
        for a in out:
            a.setflags(write=False)
        self._no_pairs[observers] = out
        return out

    def batch_noise_free(self, ctx: SensingContext, observers: np.ndarray) -> RelBatch:
        """What `stimulus` gives each of `observers` (distinct, increasing indices) without noise, as
        arrays (the batch mode): the same neighbours in the same order, the same float64 values (the
        own state as the named arrays `own_position_m`, `own_velocity_mps` in `extra`)."""
        pos, vel = ctx.position_m, ctx.velocity_mps
        obs = np.asarray(observers, dtype=np.int64)
        every = len(obs) == len(pos)  # (distinct and increasing: every row, in order)
        own_p, own_v = (pos, vel) if every else (pos[obs], vel[obs])
        d = row_norm(pos[None, :, :] - own_p[:, None, :])  # (R, N): np.linalg.norm(..., axis=2), as stimulus's per row
        vis = d <= self.p.range_m
        if not ctx.all_alive:
            vis &= np.asarray(ctx.alive, dtype=bool)
        if every:
            vis.ravel()[::len(obs) + 1] = False  # (the diagonal: nobody is its own neighbour)
        else:
            vis[np.arange(len(obs)), obs] = False
        if np.count_nonzero(vis):
            jj, kk = vis.nonzero()
            offsets = np.zeros(len(obs) + 1, dtype=np.int64)
            j = obs[jj]
            rp, rv = pos[kk] - pos[j] + 0.0, vel[kk] - vel[j] + 0.0  # (+ 0.0: the message path's, -0.0 -> 0.0)
            np.add.accumulate(np.bincount(jj, minlength=len(obs)), out=offsets[1:])
        else:  # nobody within range of anyone: zero offsets, no pairs (read-only arrays, made once per R)
            offsets, jj, rp = self._no_pairs.get(len(obs)) or self._none_in_range(len(obs))
            kk, rv = jj, rp
        # the own states as two arrays, observer r's the rows r (pos[i] + 0.0, vel[i] + 0.0), its dict on demand
        extra = (NamedRows({"own_position_m": own_p + 0.0, "own_velocity_mps": own_v + 0.0}, len(obs))
                 if self.p.own_state else None)
        return RelBatch(offsets, kk, rp, rv, jj, extra)

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.Measurements:
        p = self.p
        pos, vel = ctx.position_m, ctx.velocity_mps
        msg = pb.Measurements(header=hdr, u_rad=ctx.u_rad)
        d = np.linalg.norm(pos - pos[j], axis=1)
        for k in np.flatnonzero((d <= p.range_m) & ctx.alive).tolist():
            if k == j:
                continue
            rp = pos[k] - pos[j] + (self.rng.normal(0.0, p.position_noise_m, 3) if p.position_noise_m else 0.0)
            rv = vel[k] - vel[j] + (self.rng.normal(0.0, p.velocity_noise_mps, 3) if p.velocity_noise_mps else 0.0)
            nb = msg.neighbours.add(id=ctx.ids[k])
            nb.position_m.x, nb.position_m.y, nb.position_m.z = np.asarray(rp, float).tolist()
            nb.velocity_mps.x, nb.velocity_mps.y, nb.velocity_mps.z = np.asarray(rv, float).tolist()
        if p.own_state:
            op = pos[j] + (self.rng.normal(0.0, p.own_position_noise_m, 3) if p.own_position_noise_m else 0.0)
            ov = vel[j] + (self.rng.normal(0.0, p.own_velocity_noise_mps, 3) if p.own_velocity_noise_mps else 0.0)
            add_measurement(msg, "own_position_m", op)
            add_measurement(msg, "own_velocity_mps", ov)
        return msg
