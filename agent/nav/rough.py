"""Paper 002 section 5's rough navigation: blobs of two successive frames -> relative state.

- Range from area, z = f sqrt(A_true / A_blob). `range_model` says what A_true is:
  "silhouette" (default): the area the known shape shows along the blob's line of sight,
  A_true = A_z + A_x |x/z| + A_y |y/z| (agent.nav.measure, the EKF's own area model; x/z, y/z from
  the centroid), so a neighbour off the boresight, which also shows its radial faces obliquely,
  is not taken for a nearer one; "face_on": the paper's literal A_true = A_z, biased by up to 6.8 %
  at the edge of the field of view (docs/camera-navigation.md). x, y from the pinhole relation.
- Nearest-neighbour association between the two newest frames, on the image position predicted
  with the blob's last image velocity, gated at `gate_px`, one-to-one (Hungarian).
- Velocity from the two newest frames (NOTES-002: the printed difference uses the future frame).
  `velocity` = "dynamics" (default): the relative ROE at the newest frame that reproduce both
  frames' positions under the known relative dynamics (paper 002 Eq. 2, Keplerian; the observer's
  own commanded acceleration held over the interval as the known input, the neighbour's unknown
  control taken as zero): with T(u) the ROE -> LVLH position map, Phi, Gamma the transition and
  input matrices over dt (agent.nav.ekf),
      [ T(u_t) ; T(u_{t-dt}) Phi^-1 ] alpha_t = [ r_t ; r_{t-dt} - T(u_{t-dt}) Phi^-1 Gamma a_j ],
  six equations for the six ROE: the finite difference without its lag (a plain difference is the
  mean velocity over the interval, dt/2 late, which the relative orbit's curvature and the
  observer's own thrust turn into metres of a*da and a*de). "difference": the paper's causal
  finite difference, zdot = dz/dt, xdot = z/f du/dt + (u - cx)/f zdot, ydot likewise, then
  LVLH -> ROE with the paper's M (agent.roe.lvlh_to_roe).
A track is output from its second frame on (it needs a velocity) and dropped at its first miss.

The steps are pure functions over rows (`positions_cam` per blob, `predicted_px` per track,
`pair_costs` per (track, blob) pair, `pair_states` per matched pair), so `update_many` runs them
once over the rows of every observer of a batch step and each navigator's own `update` over its
own rows, with the same values; what is per observer stays per observer (the association, and
LAPACK's solve of the "dynamics" system: `solve_frames`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.agent.blob.blobs import Blobs
from swarmhil.agent.camera.model import R_LVLH_FROM_CAM, Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav.associate import assign
from swarmhil.agent.nav.base import Track, guarded, update_together
from swarmhil.agent.nav.ekf import input_gamma, transition
from swarmhil.agent.nav.measure import roe_position_matrix, rough_position_cam
from swarmhil.agent.roe import lvlh_to_roe, roe_to_lvlh

RANGE_MODELS = ("silhouette", "face_on")
VELOCITY_MODELS = ("dynamics", "difference")
CHOICES = {"range_model": RANGE_MODELS, "velocity": VELOCITY_MODELS}  # [nav.params] that name a choice


@dataclass
class RoughTracks:
    """A rough navigator's tracks after a frame, one row each: the blobs of that frame, matched to a
    track of the frame before or new."""

    ids: list[str]
    t_s: np.ndarray  # (T,) the frame's time
    centroid_px: np.ndarray  # (T, 2) the blob's centroid
    p_cam_m: np.ndarray  # (T, 3) the blob's camera-frame position (range from area)
    image_vel_pxps: np.ndarray  # (T, 2) centroid change over the last two frames / dt; 0 where none
    has_vel: np.ndarray  # (T,) bool: the track has an image velocity (its second frame on)
    age: np.ndarray  # (T,) int64: frames since the track was created
    hits: np.ndarray  # (T,) int64: frames with a blob

    ARRAYS = ("t_s", "centroid_px", "p_cam_m", "image_vel_pxps", "has_vel", "age", "hits")

    def __len__(self) -> int:
        return len(self.ids)

    @staticmethod
    def empty() -> "RoughTracks":
        return RoughTracks([], np.zeros(0), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0, bool),
                           np.zeros(0, np.int64), np.zeros(0, np.int64))

    @staticmethod
    def concat(parts: list["RoughTracks"]) -> "RoughTracks":
        """The rows of several navigators' tracks, navigator by navigator."""
        if len(parts) == 1:
            return parts[0]
        return RoughTracks([i for p in parts for i in p.ids],
                           *(np.concatenate([getattr(p, f) for p in parts]) for f in RoughTracks.ARRAYS))

    def rows(self, a: int, b: int, ids: list[str]) -> "RoughTracks":
        """Rows a:b (views) under the track ids `ids`."""
        return RoughTracks(ids, *(getattr(self, f)[a:b] for f in RoughTracks.ARRAYS))


def silhouette_area_m2(ray: np.ndarray, areas_m2: np.ndarray) -> np.ndarray:
    """A_z + A_x |x/z| + A_y |y/z| (M,): the area of a body in nominal attitude seen along the rays
    (M, 3) with z = 1 (agent.nav.measure module docstring)."""
    ax, ay, az = (float(a) for a in areas_m2)
    return az + ax * np.abs(ray[:, 0]) + ay * np.abs(ray[:, 1])


def positions_cam(centroid_px: np.ndarray, area_px: np.ndarray, camera: Camera, areas_m2: np.ndarray,
                  range_model: str) -> np.ndarray:
    """(M, 3) camera-frame positions of M blobs: range from area, z = f sqrt(A_true / A_blob) with A_true
    under `range_model` (module docstring), x, y from the pinhole relation. Elementwise per blob."""
    if range_model == "face_on":
        return rough_position_cam(centroid_px, area_px, camera, float(areas_m2[2]))
    ray = camera.ray(centroid_px).reshape(-1, 3)
    z = camera.focal_px * np.sqrt(silhouette_area_m2(ray, areas_m2) / np.maximum(area_px, 1e-9))
    return ray * z[:, None]


def predicted_px(tracks: RoughTracks, t_s: float) -> np.ndarray:
    """(T, 2) where each track's blob is expected at t_s: its centroid moved by its image velocity over
    t_s - its frame's time (a track without a velocity: its centroid + 0). Elementwise per track."""
    moved = tracks.image_vel_pxps * (t_s - tracks.t_s)[:, None]
    return tracks.centroid_px + np.where(tracks.has_vel[:, None], moved, 0.0)


def pair_costs(pred_px: np.ndarray, centroid_px: np.ndarray, ti: np.ndarray, bj: np.ndarray) -> np.ndarray:
    """(Q,) image distances |pred[ti] - centroid[bj]| of Q (track, blob) pairs: per pair the arithmetic of
    the (T, M) matrix np.linalg.norm(pred[:, None] - centroid[None], axis=2) (the same two squares and one sum)."""
    return np.linalg.norm(pred_px[ti] - centroid_px[bj], axis=1)


def _frame_system(u1_rad: float, dt_s: float, a_m: float, n_radps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lhs (6, 6), T(u0) Phi^-1 (3, 6), Gamma (6, 3)) of `two_frame_roe` for one frame interval; the
    navigators of a batch step share one reference u and dt, so the last few are remembered
    (read-only; the same values whether remembered or not)."""
    key = (u1_rad, dt_s, a_m, n_radps)
    hit = _SYSTEMS.get(key)
    if hit is None:
        u0_rad = u1_rad - n_radps * dt_s
        t0 = roe_position_matrix(u0_rad, n_radps) @ np.linalg.inv(transition(n_radps, dt_s))
        lhs = np.vstack((roe_position_matrix(u1_rad, n_radps), t0))
        hit = (lhs, t0, input_gamma(u0_rad, a_m, n_radps, dt_s))
        for m in hit:
            m.setflags(write=False)
        if len(_SYSTEMS) >= 8:
            _SYSTEMS.clear()
        _SYSTEMS[key] = hit
    return hit


_SYSTEMS: dict[tuple[float, float, float, float], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def solve_frames(rhs: np.ndarray, dts: np.ndarray, u1_rad: float, a_m: float, n_radps: float,
                 own_accel_mps2: np.ndarray | None, same: bool | None = None) -> np.ndarray:
    """The solve of `two_frame_roe` for one observer's P pairs: rhs (P, 6) = [r_t, r_{t-dt}] rows
    (overwritten), dts (P,); one LAPACK solve per distinct interval, with that observer's thrust term.
    A column of LAPACK's solve depends on how many right-hand sides it is solved with (OpenBLAS's
    kernels: with 1 and with 5 columns, the last bit differs now and then), so the navigators of a
    batch step each keep their own solve (`update_many`). `same`: whether dts.min() == dts.max(), if
    the caller knows it."""
    out = np.empty((len(rhs), 6))
    if same is None:
        same = bool(dts.min() == dts.max()) if len(dts) else True
    groups = [(float(dts[0]), slice(None))] if same and len(dts) else \
        [(dt, np.flatnonzero(dts == dt)) for dt in np.unique(dts).tolist()]
    for dt, rows in groups:  # one system per interval (a frame's pairs share one)
        lhs, t0, gamma = _frame_system(u1_rad, dt, a_m, n_radps)
        r = rhs[rows]
        if own_accel_mps2 is not None:
            r[:, 3:] -= t0 @ (gamma @ np.asarray(own_accel_mps2, dtype=float))
        out[rows] = np.linalg.solve(lhs, r.T).T
    return out


def two_frame_roe(r0_m: np.ndarray, r1_m: np.ndarray, u1_rad: float, dt_s: float | np.ndarray, a_m: float,
                  n_radps: float, own_accel_mps2: np.ndarray | None) -> np.ndarray:
    """The ROE (metres, neighbour relative to observer) at the newest frame that reproduce the LVLH
    positions r0 (dt before) and r1 (at the reference's mean argument of latitude u1; u0 = u1 - n dt)
    under Eq. 2 with the observer's own thrust a_j held over dt (module docstring): the 6 x 6 solve.
    r0_m, r1_m (P, 3) or (3,); dt_s a scalar or (P,); returns (P, 6) or (6,)."""
    r0, r1 = np.atleast_2d(r0_m), np.atleast_2d(r1_m)
    dts = np.broadcast_to(np.asarray(dt_s, dtype=float), (len(r1),))
    out = solve_frames(np.concatenate((r1, r0), axis=1), dts, u1_rad, a_m, n_radps, own_accel_mps2)
    return out if np.ndim(r1_m) == 2 else out[0]


def pair_states(t_s: float, u_rad: float, prev: RoughTracks, c_px: np.ndarray, p_cam_m: np.ndarray,
                spans: list[tuple[int, int, np.ndarray | None]], camera: Camera, a_m: float, n_radps: float,
                velocity: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """ROE (P, 6), LVLH position (P, 3) and velocity (P, 3) of P matched (track, blob) pairs, and their
    image velocities (P, 2): prev the pairs' tracks (rows), c_px (P, 2) and p_cam_m (P, 3) their new
    blobs; spans (start, stop, own acceleration) the rows of each observer. Elementwise per pair but
    for `solve_frames`, once per observer (module docstring: "dynamics" solves, "difference" the
    paper's finite difference); R_LVLH_FROM_CAM is a signed permutation, so its products are exact per row."""
    dt = t_s - prev.t_s
    duv = (c_px - prev.centroid_px) / dt[:, None]
    pos = p_cam_m @ R_LVLH_FROM_CAM.T
    if velocity == "dynamics":
        rhs = np.concatenate((pos, prev.p_cam_m @ R_LVLH_FROM_CAM.T), axis=1)
        roe = np.empty((len(dt), 6))
        starts = [a for a, _, _ in spans]  # whether each observer's pairs share one interval, all at once
        same = (np.minimum.reduceat(dt, starts) == np.maximum.reduceat(dt, starts)).tolist() if spans else []
        for (a, b, acc), one in zip(spans, same):
            roe[a:b] = solve_frames(rhs[a:b], dt[a:b], u_rad, a_m, n_radps, acc, one)
        pos, vel = roe_to_lvlh(roe, u_rad, n_radps)
    else:
        f, z = camera.focal_px, p_cam_m[:, 2]
        zdot = (z - prev.p_cam_m[:, 2]) / dt
        vel_cam = np.stack((z / f * duv[:, 0] + (c_px[:, 0] - camera.cx) / f * zdot,
                            z / f * duv[:, 1] + (c_px[:, 1] - camera.cy) / f * zdot, zdot), axis=1)
        vel = vel_cam @ R_LVLH_FROM_CAM.T
        roe = lvlh_to_roe(pos, vel, u_rad, n_radps)
    return roe, pos, vel, duv


_BATCH_KEYS: dict[tuple, int] = {}  # RoughNavigator.batch_key: one number per distinct setting


class RoughNavigator:
    name = "rough"

    def __init__(self, camera: Camera, shape: SpacecraftShape, a_m: float, n_radps: float, gate_px: float = 30.0,
                 range_model: str = "silhouette", velocity: str = "dynamics") -> None:
        if range_model not in RANGE_MODELS:
            raise ValueError(f"[nav.params].range_model must be one of {RANGE_MODELS} (got {range_model!r})")
        if velocity not in VELOCITY_MODELS:
            raise ValueError(f"[nav.params].velocity must be one of {VELOCITY_MODELS} (got {velocity!r})")
        self.camera = camera
        self.areas_m2 = np.asarray(shape.projected_areas_m2, dtype=float)
        self.area_true_m2 = float(self.areas_m2[2])
        self.a_m, self.n = a_m, n_radps
        self.gate_px = gate_px
        self.range_model, self.velocity = range_model, velocity
        self.state = RoughTracks.empty()
        self._next_id = 0
        key = (camera, tuple(float(a).hex() for a in self.areas_m2), float(a_m).hex(), float(n_radps).hex(),
               float(gate_px).hex(), range_model, velocity)
        self.batch_key = _BATCH_KEYS.setdefault(key, len(_BATCH_KEYS))  # (navigators of one key share every setting)

    def positions_cam(self, blobs: Blobs) -> np.ndarray:
        """(M, 3) camera-frame positions of the blobs: range from area under `range_model`."""
        return positions_cam(blobs.centroid_px, blobs.area_px, self.camera, self.areas_m2, self.range_model)

    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None) -> list[Track]:
        """Associate the frame's blobs with the tracks of the frame before (Hungarian, gated), estimate
        the matched ones, start a track per other blob; the confirmed (matched) tracks. The arithmetic
        of `update_many` with this navigator alone."""
        plan = _frame_arrays([self], t_s, u_rad, [blobs], [own_accel_mps2])
        return _commit(self, 0, t_s, plan)


@dataclass
class _FramePlan:
    """What `update_many` computed for one frame, before anything is written. Pairs: the matched
    (track, blob) pairs, navigator by navigator; next: the tracks after the frame, navigator by
    navigator (each one's matched tracks, then a new track per unmatched blob, in blob order)."""

    prev_ids: list[str]  # the tracks before the frame (all navigators' rows)
    pstart: list[int]  # (N + 1,) first pair of each navigator
    pair_track: list[int]  # (P,) the pair's track row
    pair_blob: list[int]  # (P,) the pair's blob index in its navigator's frame
    ages: list[int]  # (P,) the track's age and hits after the frame
    hits: list[int]
    roe: np.ndarray  # (P, 6)
    pos: np.ndarray  # (P, 3)
    vel: np.ndarray  # (P, 3)
    nstart: list[int]  # (N + 1,) first row of each navigator in `next`
    born: list[int]  # (N,) new tracks per navigator
    next: RoughTracks  # (ids empty: given at the commit)


def _frame_arrays(navs: list[RoughNavigator], t_s: float, u_rad: float, blobs: list[Blobs],
                  own_accel_mps2: list[np.ndarray | None]) -> _FramePlan:
    """The arithmetic of `update_many`: every navigator's positions from area, predictions, pair
    costs, association (per navigator), pair states and next tracks; no navigator is changed."""
    nav0, n_ = navs[0], len(navs)
    prev = RoughTracks.concat([nav.state for nav in navs])
    tcount = np.array([len(nav.state) for nav in navs], dtype=np.int64)
    bcount = np.array([len(b) for b in blobs], dtype=np.int64)
    tstart = np.concatenate(([0], np.cumsum(tcount))).tolist()
    bstart = np.concatenate(([0], np.cumsum(bcount)))
    one = len(blobs) == 1
    cen = blobs[0].centroid_px if one else np.concatenate([b.centroid_px for b in blobs]).reshape(-1, 2)
    area = blobs[0].area_px if one else np.concatenate([b.area_px for b in blobs])
    p_cam = positions_cam(cen, area, nav0.camera, nav0.areas_m2, nav0.range_model)
    # every navigator's (track, blob) pairs, track-major: each track of navigator k with each of its blobs
    npairs = tcount * bcount
    qstart = np.concatenate(([0], np.cumsum(npairs)))
    owner = np.repeat(np.arange(n_), npairs)
    ti = np.repeat(np.arange(len(prev)), np.repeat(bcount, tcount))
    bj = bstart[owner] + (np.arange(int(qstart[-1])) - qstart[owner]) % np.maximum(bcount[owner], 1)
    cost = pair_costs(predicted_px(prev, t_s), cen, ti, bj)
    pair_track: list[int] = []
    pair_blob: list[int] = []
    pstart = [0]
    spans: list[tuple[int, int, np.ndarray | None]] = []
    qs, ts, tc, bc = qstart.tolist(), tstart, tcount.tolist(), bcount.tolist()
    for k in range(n_):
        if qs[k + 1] > qs[k]:
            for a, b in assign(cost[qs[k]:qs[k + 1]].reshape(tc[k], bc[k]), nav0.gate_px):
                pair_track.append(ts[k] + a)
                pair_blob.append(b)
        pstart.append(len(pair_track))
        if pstart[k + 1] > pstart[k]:
            spans.append((pstart[k], pstart[k + 1], own_accel_mps2[k]))
    g = np.array(pair_track, dtype=np.int64)
    powner = np.repeat(np.arange(n_), np.diff(pstart))
    b_glob = bstart[powner] + np.array(pair_blob, dtype=np.int64)
    matched = prev.rows(0, len(prev), prev.ids) if len(g) == len(prev) and (g == np.arange(len(g))).all() else \
        RoughTracks([], *(getattr(prev, f)[g] for f in RoughTracks.ARRAYS))
    roe, pos, vel, duv = pair_states(t_s, u_rad, matched, cen[b_glob], p_cam[b_glob], spans, nav0.camera, nav0.a_m,
                                     nav0.n, nav0.velocity)
    # the tracks after the frame: per navigator its matched pairs, then its unmatched blobs
    free = np.ones(len(cen), bool)
    free[b_glob] = False
    new = np.flatnonzero(free)
    bowner = np.repeat(np.arange(n_), bcount)[new]
    order = np.argsort(np.concatenate((2 * powner, 2 * bowner + 1)), kind="stable")
    p_, m_ = len(g), len(new)
    born = np.bincount(bowner, minlength=n_)
    ages, hits = matched.age + 1, matched.hits + 1
    nxt = RoughTracks(
        [], np.full(p_ + m_, t_s, dtype=float), np.concatenate((cen[b_glob], cen[new]))[order],
        np.concatenate((p_cam[b_glob], p_cam[new]))[order], np.concatenate((duv, np.zeros((m_, 2))))[order],
        np.concatenate((np.ones(p_, bool), np.zeros(m_, bool)))[order],
        np.concatenate((ages, np.zeros(m_, np.int64)))[order], np.concatenate((hits, np.ones(m_, np.int64)))[order])
    nstart = np.concatenate(([0], np.cumsum(np.diff(pstart) + born))).tolist()
    return _FramePlan(prev.ids, pstart, pair_track, pair_blob, ages.tolist(), hits.tolist(), roe, pos, vel, nstart,
                      born.tolist(), nxt)


def _commit_frame(navs: list[RoughNavigator], t_s: float, u_rad: float, blobs: list[Blobs],
                  plan: _FramePlan) -> list[list[Track] | Exception]:
    """Each navigator's part of `plan` written (`_commit`), or the exception of its part."""
    return [guarded(_commit, nav, k, t_s, plan) for k, nav in enumerate(navs)]


def _commit(nav: RoughNavigator, k: int, t_s: float, plan: _FramePlan) -> list[Track]:
    """Write navigator k's part of `plan` into it (its tracks after the frame, its next id) and return
    its output tracks, as its own `update` does."""
    a, b = plan.pstart[k], plan.pstart[k + 1]
    ids = [plan.prev_ids[g] for g in plan.pair_track[a:b]]
    out = [Track(tid, plan.roe[r], plan.pos[r], plan.vel[r], None, plan.ages[r], plan.hits[r], plan.pair_blob[r])
           for tid, r in zip(ids, range(a, b))]
    k0 = nav._next_id
    ids += [f"r{k0 + j}" for j in range(plan.born[k])]
    nav.state = plan.next.rows(plan.nstart[k], plan.nstart[k + 1], ids)
    nav._next_id = k0 + plan.born[k]
    return out


def update_many(navs: list[RoughNavigator], t_s: float, u_rad: float, blobs: list[Blobs],
                own_accel_mps2: list[np.ndarray | None]) -> list[list[Track] | Exception]:
    """`update` of several navigators for one frame (navs[k] sees blobs[k] with its own acceleration
    own_accel_mps2[k]: the observers of a batch step), every observer's blobs and tracks stacked: one
    pass of positions from area, predictions and pair costs over all of them, the association per
    observer, one pass of pair states (one LAPACK solve per observer: `solve_frames`) and of the
    tracks after the frame. Each navigator ends in the state its own `update` gives, bit for bit:
    every step is elementwise per blob, track or pair, or per observer (tests/test_nav_rough_batched.py).
    Navigators of different settings (`batch_key`) are updated one by one.

    Returns each navigator's tracks, or the exception its own `update` would have raised (then its
    state is undefined: the caller resets it). Nothing is written before the arithmetic of every
    observer is done: if it raises, each navigator runs its own `update`."""
    return update_together(navs, t_s, u_rad, blobs, own_accel_mps2, _frame_arrays, _commit_frame)
