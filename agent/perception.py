"""Perception of the flight software for the `scene` stimulus (issue 4): camera -> blobs ->
navigation, turned into the controller's Observation, the telemetry tracks and debug images.

Which tracks the controller gets: every track the navigator outputs (confirmed tracks) goes to the
telemetry; the controller gets those whose ROE estimate is navigation-grade, i.e. the 1-sigma
(sqrt of the diagonal of the track covariance) of each of a*da, a*dex, a*dey, a*dix, a*diy is at
most [nav].control_max_sigma_m (0: no such test; estimators without a covariance always pass).
These are the components the behavioural law's gains act on; a*dl has no gain (it only enters the
choice of behaviour, against thresholds of 100 m and 300 m) and is left out. A track
is confirmed after three frames, but its a*da and a*de are then still wrong by tens of metres
(velocity from 20 s of bearings): acting on that costs dV for nothing. docs/camera-navigation.md
gives the physical argument for the value used in the scenarios.

The agent only uses what its camera would see: the poses in the camera frame (to render or, in
the paper's exact mode, to measure area and centroid exactly). The pointing error in the
stimulus is a fact of the simulation, not known to the flight software, and is not used.
"""
from __future__ import annotations

import io
from typing import Any

import numpy as np

from swarmhil.agent.camera.model import Camera, quat_to_matrix
from swarmhil.agent.camera.render import compose_frame
from swarmhil.agent.controller import Observation
from swarmhil.agent.nav.base import Track, observation_arrays
from swarmhil.agent.blob.blobs import exact_blobs_many
from swarmhil.agent.nav.ekf import EkfConfig, EkfNavigator, update_many
from swarmhil.agent.nav.pipeline import VisionNav
from swarmhil.agent.nav.rough import CHOICES as ROUGH_CHOICES
from swarmhil.agent.nav.rough import RoughNavigator
from swarmhil.agent.nav.rough import update_many as rough_update_many
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.optional import require

NAV_FIELDS = {"imaging", "navigator", "backend", "min_pixels", "params", "debug_image_period_s", "debug_image_downsample",
              "control_max_sigma_m", "control_sigma_model"}


def nav_config(table: dict[str, Any] | None) -> dict[str, Any]:
    """Validated [nav] table with defaults (errors name the field)."""
    t = dict(table or {})
    unknown = sorted(set(t) - NAV_FIELDS)
    if unknown:
        raise ValueError(f"[nav].{unknown[0]} is not a known field; known: {sorted(NAV_FIELDS)}")
    cfg = {"imaging": t.get("imaging", "render"), "navigator": t.get("navigator", "ekf"),
           "backend": t.get("backend", "numpy"), "min_pixels": int(t.get("min_pixels", 2)),
           "params": dict(t.get("params", {})), "debug_image_period_s": float(t.get("debug_image_period_s", 0.0)),
           "debug_image_downsample": int(t.get("debug_image_downsample", 4)),
           "control_max_sigma_m": float(t.get("control_max_sigma_m", 0.0)),
           "control_sigma_model": t.get("control_sigma_model", "mixture")}
    if cfg["imaging"] not in ("exact", "render"):
        raise ValueError(f"[nav].imaging must be 'exact' or 'render' (got {cfg['imaging']!r})")
    if cfg["navigator"] not in ("rough", "ekf"):
        raise ValueError(f"[nav].navigator must be 'rough' or 'ekf' (got {cfg['navigator']!r})")
    if cfg["backend"] not in ("numpy", "numba", "auto"):
        raise ValueError(f"[nav].backend must be 'numpy', 'numba' or 'auto' (got {cfg['backend']!r})")
    if cfg["debug_image_period_s"] < 0 or cfg["debug_image_downsample"] < 1:
        raise ValueError("[nav].debug_image_period_s must be >= 0 and debug_image_downsample >= 1")
    if cfg["control_sigma_model"] not in ("mixture", "quiet"):
        raise ValueError(f"[nav].control_sigma_model must be 'mixture' or 'quiet' (got {cfg['control_sigma_model']!r})")
    if not cfg["control_max_sigma_m"] >= 0:
        raise ValueError(f"[nav].control_max_sigma_m must be >= 0 (got {cfg['control_max_sigma_m']!r})")
    _check_nav_params(cfg["navigator"], cfg["params"])
    return cfg


def _check_nav_params(navigator: str, params: dict[str, Any]) -> None:
    """[nav.params] are the chosen navigator's settings: EkfConfig's fields, or the rough navigator's gate_px,
    range_model and velocity; each a finite number >= 0 (confirm_hits and max_misses integers), or one of
    the named choices (agent/nav/rough.py CHOICES)."""
    import dataclasses
    import inspect
    import math

    if navigator == "ekf":
        known = {f.name for f in dataclasses.fields(EkfConfig)}
    else:  # what make_navigator passes on as keywords: the constructor's arguments after the fixed ones
        known = set(list(inspect.signature(RoughNavigator.__init__).parameters)[5:])
    for key, val in params.items():
        if key not in known:
            raise ValueError(f"[nav.params].{key} is not a setting of the {navigator!r} navigator; known: {sorted(known)}")
        if navigator == "rough" and key in ROUGH_CHOICES:
            if val not in ROUGH_CHOICES[key]:
                raise ValueError(f"[nav.params].{key} must be one of {list(ROUGH_CHOICES[key])} (got {val!r})")
            continue
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val) or val < 0:
            raise ValueError(f"[nav.params].{key} must be a finite number >= 0 (got {val!r})")
        if key == "output_max_misses" and not float(val).is_integer():
            raise ValueError(f"[nav.params].{key} must be an integer >= 0 (got {val!r})")
        if key in ("confirm_hits", "max_misses") and (not float(val).is_integer() or val < 1):
            raise ValueError(f"[nav.params].{key} must be an integer >= 1 (got {val!r})")


GAINED_ROE = [0, 2, 3, 4, 5]  # a*da, a*dex, a*dey, a*dix, a*diy: the components with a gain in paper 002's law (missions/p002_sabatini/fsw)


def control_tracks(tracks: list[Track], max_sigma_m: float, model: str = "mixture") -> list[Track]:
    """Tracks whose 1-sigma of a*da, a*de and a*di components is at most max_sigma_m (all of them if
    max_sigma_m is 0 or a track has no covariance): those the controller may act on (module docstring).
    `model` "quiet": the 1-sigma of the IMM's quiet model where the track has one (has the estimate
    converged, were the neighbour not manoeuvring), else of the track's covariance."""
    if max_sigma_m <= 0:
        return list(tracks)

    def cov(t: Track) -> np.ndarray | None:
        return t.quiet_covariance_m2 if model == "quiet" and t.quiet_covariance_m2 is not None else t.covariance_m2

    return [t for t in tracks if cov(t) is None
            or float(np.sqrt(np.max(np.diagonal(np.asarray(cov(t)))[GAINED_ROE]))) <= max_sigma_m]


class Perception:
    def __init__(self, a_m: float, n_radps: float, cfg: dict[str, Any], camera_cfg: dict[str, Any] | None = None) -> None:
        cam = None
        if camera_cfg:
            px = int(camera_cfg.get("image_px", 1080))
            cam = Camera(width_px=px, height_px=px, focal_px=float(camera_cfg.get("focal_px", 1000.0)),
                         max_range_m=float(camera_cfg.get("detection_range_m", 500.0)))
        self.cfg = cfg
        self._make_vision = lambda: VisionNav(a_m, n_radps, imaging=cfg["imaging"], navigator=cfg["navigator"], camera=cam,
                                              backend=cfg["backend"], min_pixels=cfg["min_pixels"], nav_params=cfg["params"])
        self.vision = self._make_vision()
        self.tracks: list[Track] = []
        self._next_image_t = 0.0
        self.warm_up()

    def warm_up(self) -> None:
        """Run the whole pipeline on two synthetic frames, then start afresh. Loading the compiled
        renderer and the lazy imports of the first frame took over the 5 s lockstep deadline when
        20 agents started together on 2 cores (every agent missed step 0); done here, before the
        agent announces itself alive, the plant's start-up wait covers it."""
        pos, rot = np.array([[0.5, -0.5, 200.0]]), np.eye(3)[None]
        for k in range(2):
            self.vision.step(10.0 * k, 0.0, pos, rot, k, np.zeros(3))
        self.reset()

    def reset(self) -> None:
        """Forget every track and start navigation afresh (after a handled fault)."""
        self.vision = self._make_vision()
        self.tracks = []

    def observe(self, stim: pb.SceneStimulus, own_accel_mps2: np.ndarray) -> Observation:
        n = len(stim.bodies)
        pos = np.array([[b.position_cam_m.x, b.position_cam_m.y, b.position_cam_m.z] for b in stim.bodies]).reshape(n, 3)
        rot = np.array([quat_to_matrix(np.array([b.attitude_cam.w, b.attitude_cam.x, b.attitude_cam.y, b.attitude_cam.z]))
                        for b in stim.bodies]).reshape(n, 3, 3)
        return self.observe_arrays(int(stim.header.step), stim.header.t, stim.u_rad, pos, rot, own_accel_mps2)

    def observe_arrays(self, step: int, t_s: float, u_rad: float, pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray,
                       own_accel_mps2: np.ndarray) -> Observation:
        """`observe` of a stimulus given as its values: the bodies' camera-frame positions (n, 3) and
        attitudes body -> camera (n, 3, 3) (the batch mode, deploy/batch.py: no message built or read)."""
        self.tracks = self.vision.step(t_s, u_rad, pos_cam_m, rot_body_to_cam, step, own_accel_mps2)
        return self._observation(step, t_s, u_rad)

    def observe_blobs(self, step: int, t_s: float, u_rad: float, blobs: Any, own_accel_mps2: np.ndarray) -> Observation:
        """`observe_arrays` of a frame whose blobs are already measured (the batch mode's exact imaging:
        every spacecraft's blobs at once, agent/blob/blobs.py exact_blobs_many)."""
        self.tracks = self.vision.update(t_s, u_rad, blobs, own_accel_mps2)
        return self._observation(step, t_s, u_rad)

    def observe_tracks(self, step: int, t_s: float, u_rad: float, tracks: list[Track]) -> Observation:
        """`observe_blobs` of a frame whose navigator update ran outside this object (the batch mode
        updates the EKF navigators of a step together: agent/nav/ekf.py update_many): its tracks."""
        self.tracks = tracks
        return self._observation(step, t_s, u_rad)

    def _observation(self, step: int, t_s: float, u_rad: float) -> Observation:
        ids, rp, rv = observation_arrays(control_tracks(self.tracks, self.cfg["control_max_sigma_m"], self.cfg["control_sigma_model"]))
        return Observation(step=step, t_s=t_s, u_rad=u_rad, neighbour_ids=ids, rel_position_m=rp, rel_velocity_mps=rv)

    def track_messages(self) -> list[pb.TrackEstimate]:
        out = []
        for tr in self.tracks:
            m = pb.TrackEstimate(track=tr.track_id, roe_m=[float(x) for x in tr.roe_m], age_steps=int(tr.age_steps))
            if tr.covariance_m2 is not None:
                m.covariance_m2.extend(float(x) for x in np.asarray(tr.covariance_m2).ravel())
            m.position_m.x, m.position_m.y, m.position_m.z = np.asarray(tr.position_m, float).tolist()
            m.velocity_mps.x, m.velocity_mps.y, m.velocity_mps.z = np.asarray(tr.velocity_mps, float).tolist()
            out.append(m)
        return out

    def debug_image(self, t_s: float) -> bytes | None:
        """PNG of the last frame, downsampled (block max, so one-pixel blobs stay visible), at most every debug_image_period_s; None otherwise."""
        period = self.cfg["debug_image_period_s"]
        if period <= 0 or t_s + 1e-9 < self._next_image_t:
            return None
        self._next_image_t = t_s + period

        Image = require("PIL.Image", "debug images ([nav] debug_image_period_s)")

        frame = compose_frame(self.vision.last_stacks, self.vision.renderer.camera)
        if self.cfg["imaging"] == "exact":  # no image in the paper's exact mode: draw the blob centroids
            for (u, v) in self.vision.last_blobs.centroid_px:
                r, c = int(v), int(u)
                frame[max(r - 2, 0):r + 3, max(c - 2, 0):c + 3] = self.vision.renderer.detector.signal_e
        d = self.cfg["debug_image_downsample"]
        h, w = (frame.shape[0] // d) * d, (frame.shape[1] // d) * d
        small = frame[:h, :w].reshape(h // d, d, w // d, d).max(axis=(1, 3))
        img = np.clip(small / self.vision.renderer.detector.signal_e * 255.0, 0, 255).astype(np.uint8)
        buf = io.BytesIO()
        Image.fromarray(img, mode="L").save(buf, format="PNG")
        return buf.getvalue()


def observe_many(perceptions: list[Perception], step: int, t_s: float, u_rad: float, offsets: np.ndarray,
                 position_cam_m: np.ndarray, attitude_wxyz: np.ndarray, own_accel_mps2: list[np.ndarray],
                 exact: bool = False) -> list[Observation | Exception]:
    """`observe_arrays` of several spacecraft's perceptions for one frame (the batch mode,
    agent/batch.py BatchPerception): perception r sees the bodies offsets[r]:offsets[r+1] with
    camera-frame positions (P, 3) and attitude quaternions w, x, y, z (P, 4) (matrices as `observe`
    makes them: quat_to_matrix is elementwise, all rows at once give each row its own). Each one's
    imaging (`exact`: the paper's exact blobs of every scene at once, exact_blobs_many, when all share
    one camera and shape), then the navigators (the EKF ones together, agent/nav/ekf.py update_many,
    the rough ones together, agent/nav/rough.py update_many: bit for bit each one's own update), then
    each one's observation. Returns per perception its
    Observation, or the exception its own `observe_arrays` would have raised (its state is then
    undefined: reset it)."""
    rot = quat_to_matrix(attitude_wxyz).reshape(-1, 3, 3)
    pos = np.asarray(position_cam_m, dtype=float).reshape(-1, 3)
    off = np.asarray(offsets, dtype=np.int64).tolist()
    blobs = None
    if exact and perceptions:
        r0 = perceptions[0].vision.renderer
        try:
            blobs = exact_blobs_many(pos, rot, offsets, r0.camera, r0.shape)
        except Exception:  # noqa: BLE001 - then each spacecraft's own, which faults alone (below)
            blobs = None
    got: list[Any] = []  # per perception: its blobs, tracks, observation or the exception that ended it
    for r, per in enumerate(perceptions):
        try:
            if blobs is not None:
                b, stacks = blobs[r], None
            else:  # (fresh arrays, as the agent's from its message)
                b, stacks = per.vision.image(pos[off[r]:off[r + 1]].copy(), rot[off[r]:off[r + 1]].copy(), step)
            per.vision.keep(b, stacks)
            got.append(b)
        except Exception as e:  # noqa: BLE001 - that spacecraft's fault alone
            got.append(e)
    ok = [r for r, b in enumerate(got) if not isinstance(b, Exception)]
    navs = [perceptions[r].vision.navigator for r in ok]
    many = None
    if navs and all(type(nav) is EkfNavigator for nav in navs):
        many = update_many
    elif navs and all(type(nav) is RoughNavigator for nav in navs):
        many = rough_update_many
    if many is not None:
        for r, res in zip(ok, many(navs, t_s, u_rad, [got[r] for r in ok], [own_accel_mps2[r] for r in ok])):
            got[r] = res
    else:
        for r in ok:
            try:
                got[r] = perceptions[r].vision.navigator.update(t_s, u_rad, got[r], own_accel_mps2[r])
            except Exception as e:  # noqa: BLE001 - that spacecraft's fault alone
                got[r] = e
    for r, per in enumerate(perceptions):
        if not isinstance(got[r], Exception):
            try:
                got[r] = per.observe_tracks(step, t_s, u_rad, got[r])
            except Exception as e:  # noqa: BLE001 - that spacecraft's fault alone
                got[r] = e
    return got
