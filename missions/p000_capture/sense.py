"""Sensing kind `p000-landmarks` (paper 000 §2.2, §3.2.2): what a capture agent measures.

For every spacecraft j, one Measurements message with the names of the room's contract
(missions/p000_capture/contract.py, which the flight software reads with), here as measured:

    p000_q_body_to_lvlh   own attitude, body -> CW frame. Stands for a star tracker: the plant flies
                          attitude in an inertial frame aligned with the CW frame at t = 0
                          (plant/mission_world.py), so the sensor reports q_z(-n t) (x)
                          q_body_to_inertial (the CW frame turns at n about +z).
    p000_omega_body_radps own body rate (a gyro: the inertial rate, body axes).
    p000_position_m       own position and velocity in the CW frame centred on the target's initial
    p000_velocity_mps     position; stands for precise relative navigation (e.g. carrier-phase
                          differential GNSS to the frame's origin), ideal: the truth row minus
                          the target's initial position (0 in the scenarios).
    p000_landmarks_body_m landmark returns in the body (sensor) frame: the target's surface
                          landmarks (Fibonacci set, fixed in the target body frame) that face
                          the sensor, lie within `range_m` (R_l) and inside the full cone
                          `fov_full_deg` about body +x; Gaussian noise `noise_m` per axis; a
                          binomial `outlier_fraction` of the returns replaced by points uniform
                          in the cone out to R_l.
    p000_landmark_ids     landmark index, -1 for an outlier.
    p000_surface_rel_m    agent -> closest point of the true surface (CW frame), present only
                          within `proximity_range_m` (R_h).

Neighbours within `neighbour_range_m` (R_h) go in msg.neighbours (truth relative states; they
become Observation.rel_*). The noise of agent j at step k comes from a generator seeded by
([run].seed, NOISE_TAG, k, j): the draws do not depend on the order in which the plant asks.
This is the synthetic sensor of tests/missions/test_p000_closed_loop.py, on the plant's truth.
The landmark set and the closest surface point use the contract's geometry (pure functions; the
plant imports no flight software: docs/architecture.md "Mission rooms (issue 25)").
"""
from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import add_measurement
from swarmhil.missions.p000_capture import contract as c
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.sensing.builtin import RelBatch
from swarmhil.plant.sensing.registry import SensingContext, keyed_rng, register_sensing

KIND = c.SENSING_KIND
NOISE_TAG = 0x0C0


class P000Params(BaseModel):
    """[sensing.params] of `p000-landmarks` (defaults: docs/paper000.md, Table 1)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    target_id: str = "target"                               # a kinematic [[body]] with an ellipsoid shape
    landmarks: int = Field(400, ge=1)                       # surface landmarks (Fibonacci set)
    range_m: float = Field(8.5, gt=0)                       # R_l
    fov_full_deg: float = Field(75.0, gt=0, lt=180)         # full cone about body +x
    noise_m: float = Field(0.02, ge=0)                      # 1 sigma per axis
    outlier_fraction: float = Field(0.1, ge=0, le=1)
    proximity_range_m: float = Field(5.5, gt=0)             # R_h: surface proximity
    neighbour_range_m: float = Field(5.5, gt=0)             # R_h: neighbours


def quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product, scalar first; q may be (N, 4) (each row times p: the same elementwise
    operations as row by row, so the same bits)."""
    pw, px, py, pz = p
    qw, qx, qy, qz = np.moveaxis(np.asarray(q), -1, 0)
    return np.stack([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw], axis=-1)


def inertial_to_cw(q_body_to_inertial: np.ndarray, n_radps: float, t_s: float) -> np.ndarray:
    """Body -> CW-frame attitude from the body -> (inertial frame aligned with CW at t = 0) one."""
    h = -0.5 * n_radps * t_s
    return quat_mul(np.array([np.cos(h), 0.0, 0.0, np.sin(h)]), q_body_to_inertial)


def visible_landmarks(rel_m: np.ndarray, normals: np.ndarray, bore: np.ndarray, p: P000Params) -> np.ndarray:
    """Which landmarks a sensor sees: facing it, within R_l, inside the cone about `bore`. One
    sensor: rel_m (K, 3), bore (3,) -> (K,); N sensors: (N, K, 3), (N, 3) -> (N, K), row j the
    same bits as sensor j's alone (the norm over the last axis, einsum's and matmul's per-row sums:
    checked equal row by row, tests/test_batch_missions.py)."""
    half = np.radians(p.fov_full_deg / 2)
    dist = np.linalg.norm(rel_m, axis=-1)
    if rel_m.ndim == 2:
        facing, along = np.einsum("ij,ij->i", normals, -rel_m), rel_m @ bore
    else:
        facing, along = np.einsum("ij,nij->ni", normals, -rel_m), np.matmul(rel_m, bore[:, :, None])[:, :, 0]
    return (facing > 0) & (dist <= p.range_m) & (along >= np.cos(half) * dist)


def landmark_returns(rng: np.random.Generator, rel_m: np.ndarray, normals: np.ndarray, bore: np.ndarray,
                     p: P000Params, vis: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Returns (CW frame, relative to the sensor) and landmark ids (-1: outlier) of one sensor
    (`vis`: its `visible_landmarks`, when computed with other sensors')."""
    half = np.radians(p.fov_full_deg / 2)
    if vis is None:
        vis = visible_landmarks(rel_m, normals, bore, p)
    ids = vis.reshape(-1).nonzero()[0]  # (np.flatnonzero without its wrappers)
    ret = rel_m[ids] + rng.normal(0.0, p.noise_m, (len(ids), 3))  # (the rows of vis, in order)
    n_out = int(rng.binomial(len(ret), p.outlier_fraction)) if len(ret) else 0
    if n_out:
        dirs = rng.normal(size=(n_out, 3))
        dirs -= (dirs @ bore)[:, None] * bore[None, :]  # np.outer's product
        dirs /= np.sqrt(np.add.reduce(dirs * dirs, axis=1, keepdims=True))  # np.linalg.norm(axis=1)'s sum
        ang = rng.uniform(0.0, half, n_out)
        u = np.cos(ang)[:, None] * bore + np.sin(ang)[:, None] * dirs
        ret[:n_out] = u * rng.uniform(1.0, p.range_m, n_out)[:, None]
        ids[:n_out] = -1
    return ret, ids


@register_sensing(KIND, validate=P000Params.model_validate)
class P000LandmarkKind:
    message = pb.Measurements

    def __init__(self, scenario: PlantConfig) -> None:
        self.p = P000Params.model_validate(scenario.sensing.get("params", {}))
        body = next((b for b in scenario.bodies if b.id == self.p.target_id), None)
        if body is None:
            raise ValueError(f"[sensing.params].target_id {self.p.target_id!r} is not a [[body]]; "
                             f"known: {[b.id for b in scenario.bodies]}")
        if body.shape is None or body.shape.kind != "ellipsoid" or body.motion.kind != "kinematic":
            raise ValueError(f"p000-landmarks needs [[body]] {body.id!r} with shape.kind = 'ellipsoid' and "
                             f"motion.kind = 'kinematic'")
        if scenario.fidelity != "cw":
            raise ValueError("p000-landmarks measures in the CW frame: [plant].fidelity must be 'cw'")
        if any(s.inertia_kgm2 is None for s in scenario.spacecraft):
            raise ValueError("p000-landmarks reports attitude: every [[spacecraft]] needs inertia_kgm2")
        self.semi_axes = np.asarray(body.shape.semi_axes_m, float)
        self.origin = np.asarray(body.motion.position_m, float)
        self.lm_body, self.nrm_body = c.surface_landmarks(self.semi_axes, self.p.landmarks)
        self.seed = int(scenario.seed)

    def _step_truth(self, ctx: SensingContext) -> dict[str, Any]:
        """What every observer of the step shares, computed once for all (issue 29): the target's
        pose and landmarks, each spacecraft's CW attitude and its matrix, who sees whom."""
        bt = next(b for b in ctx.world.body_truth() if b.spec.id == self.p.target_id)
        rot = c.dcm(bt.attitude_q)
        q, w = ctx.world.attitude_wxyz()
        q_cw = inertial_to_cw(q, float(ctx.world.n_radps), ctx.t_s)
        pos = ctx.position_m
        near = (np.linalg.norm(pos[None, :, :] - pos[:, None, :], axis=2) <= self.p.neighbour_range_m) & ctx.alive
        np.fill_diagonal(near, False)
        return {"ell": c.Ellipsoid(bt.position_m, rot, self.semi_axes), "lm": bt.position_m + self.lm_body @ rot.T,
                "nrm": self.nrm_body @ rot.T, "q_cw": q_cw, "rot": c.dcm(q_cw), "w": w,
                "near": [row.nonzero()[0] for row in near]}  # (each row's np.flatnonzero)

    def _measure(self, ctx: SensingContext, tr: dict[str, Any], j: int, rel_m: np.ndarray | None = None,
                 vis: np.ndarray | None = None,
                 surface: tuple[float, np.ndarray] | None = None) -> list[tuple[str, np.ndarray]]:
        """Spacecraft j's named measurements, in the message's order (one noise generator per
        (seed, step, j): the same draws whoever asks and in whatever order); `rel_m`, `vis`,
        `surface`: its landmarks relative to it, their visibility and its (signed distance, closest
        point) on the true surface, when computed with the other observers'."""
        p = self.p
        r = ctx.position_m[j]
        q_cw, rot = tr["q_cw"][j], tr["rot"][j]
        rng = keyed_rng(self.seed, NOISE_TAG, int(ctx.step), int(j))
        ret, ids = landmark_returns(rng, tr["lm"] - r if rel_m is None else rel_m, tr["nrm"], rot[:, 0], p, vis)
        # each a float64 array of its own (copies of the rows of shared arrays): what the agent
        # reads from the message (`measurements_to_dict`), as the batch mode hands it over
        out = [(c.Q_BODY_TO_LVLH, np.array(q_cw, dtype=float)), (c.OMEGA_BODY_RADPS, np.array(tr["w"][j], dtype=float)),
               (c.POSITION_M, np.asarray(r - self.origin, dtype=float)),
               (c.VELOCITY_MPS, np.array(ctx.velocity_mps[j], dtype=float)),
               (c.LANDMARKS_BODY_M, np.asarray(ret @ rot, dtype=float).reshape(-1, 3)),
               (c.LANDMARK_IDS, ids.astype(float))]
        sd, x_s = c.surface_frame(tr["ell"], r)[:2] if surface is None else surface
        if sd <= p.proximity_range_m:
            out.append((c.SURFACE_REL_M, np.asarray(x_s - r, dtype=float)))
        return out

    def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.Measurements:
        tr = ctx.cached("p000.truth", lambda: self._step_truth(ctx))
        msg = pb.Measurements(header=hdr, u_rad=ctx.u_rad)
        pos, vel = ctx.position_m, ctx.velocity_mps
        r = pos[j]
        near = tr["near"][j]
        if len(near):
            ids = ctx.ids
            for k, dp, dv in zip(near.tolist(), (pos[near] - r).tolist(), (vel[near] - vel[j]).tolist()):
                nb = msg.neighbours.add(id=ids[k])
                nb.position_m.x, nb.position_m.y, nb.position_m.z = dp
                nb.velocity_mps.x, nb.velocity_mps.y, nb.velocity_mps.z = dv
        for name, values in self._measure(ctx, tr, j):
            add_measurement(msg, name, values)
        return msg

    def batch(self, ctx: SensingContext, observers: np.ndarray) -> RelBatch:
        """What `stimulus` gives each of `observers` (distinct, increasing indices), as arrays (the
        batch mode, issue 29): the same neighbours in the same order with the same float64 relative
        states, and each observer's named measurements in `extra` as the agent reads them from the
        message (`measurements_to_dict`: a float64 array of each one's shape)."""
        tr = ctx.cached("p000.truth", lambda: self._step_truth(ctx))
        pos, vel = ctx.position_m, ctx.velocity_mps
        obs = np.asarray(observers, dtype=np.int64).tolist()
        near = [tr["near"][j] for j in obs]
        counts = np.array([len(n) for n in near], dtype=np.int64)
        offsets = np.zeros(len(obs) + 1, dtype=np.int64)
        np.add.accumulate(counts, out=offsets[1:])
        nb = np.concatenate(near).astype(np.int64) if len(obs) else np.zeros(0, dtype=np.int64)
        owner = np.repeat(np.arange(len(obs)), counts)
        j_of = np.asarray(obs, dtype=np.int64)[owner]
        rel = tr["lm"][None, :, :] - pos[obs][:, None, :]  # (R, K, 3): each row tr["lm"] - r, as _measure's
        vis = visible_landmarks(rel, tr["nrm"], tr["rot"][obs][:, :, 0], self.p)
        sd, x_s, _ = c.surface_frames([tr["ell"]] * len(obs), pos[obs])
        extra = [dict(self._measure(ctx, tr, j, rel[r], vis[r], (sd[r], x_s[r]))) for r, j in enumerate(obs)]
        return RelBatch(offsets, nb, pos[nb] - pos[j_of], vel[nb] - vel[j_of], owner, extra)
