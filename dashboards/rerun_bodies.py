"""What the viewer draws of each spacecraft and body besides its point (issue 18, issue 12 "Viewer").

`SceneSpec.from_config` reads the resolved configuration of a run (deploy/scenario.py `resolved()`,
or the recording's metadata "swarmhil.config": dashboards/run_config.py) once; the logger
(dashboards/rerun_bridge.py) then logs, per spacecraft, a frame `world/sc/<id>` (Transform3D:
truth position and attitude in LVLH) with these children, all static in the body frame:

- camera (paper 002, sensing kind `rel` or `scene`): a `Pinhole` at `world/sc/<id>/camera`, mounted
  as agent/camera/model.py R_LVLH_FROM_CAM (boresight +y LVLH, image down = -x, right = -z; the
  camera frame is x right, y down, z boresight: Rerun's RDF). Those spacecraft fly no attitude
  (plant/world.py): their frame is LVLH (identity), so the frustum looks along-track. With debug
  frames on ([nav].debug_image_period_s > 0) the agents' frames (`sc/<id>/tm/image`) are logged
  under it as `world/sc/<id>/camera/image`; the pinhole's size is that of the downsampled image.
- sensor cone (a landmark kind, registered by its room's report: paper 000's `p000-landmarks`):
  line strips of the full cone `fov_full_deg` about body +x out to `range_m`, and the landmark
  returns of each step (the kind's points name, in the body frame) as points, outliers (its ids
  name = -1) red.
- body axes (TransformAxes3D), x red, y green, z blue.

Bodies that are not spacecraft get a frame `world/targets/<id>` with their truth attitude and their
`[[body]].shape` (ellipsoid, or spheres) as Ellipsoids3D, so a tumbling target rotates.

Thrust (`world/thrust`): the acceleration the plant applied over the step (truth accel_cmd_mps2)
as an arrow from each spacecraft, `thrust_scale_s2` metres per m/s^2 (display lengths are set
from the size of the swarm at the first truth: `display_lengths`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmhil.bus.discovery import import_role

CAMERA_KINDS = ("rel", "scene")           # plant/sensing/builtin.py: paper 002's camera
LANDMARK_KINDS: dict[str, tuple[str, str]] = {}
"""Sensing kinds whose Measurements carry landmark returns in the body frame: kind -> (name of the
(K, 3) points, name of the (K,) ids, -1 an outlier). A room's report registers its own
(`register_landmark_kind`; paper 000's), the viewer loads the reports when it reads a run."""


def register_landmark_kind(kind: str, points_name: str, ids_name: str) -> None:
    """The viewer's hook for a mission's landmark sensor (called by the room's report on import)."""
    LANDMARK_KINDS[kind] = (points_name, ids_name)


def landmark_kinds() -> dict[str, tuple[str, str]]:
    """Every registered landmark kind, after importing every room's report (bus/discovery.py)."""
    import_role("report")
    return LANDMARK_KINDS
UNLIMITED_ACCEL_MPS2 = 1.0                # a limit above this is no limit (servicing-6: 1e9)

# agent/camera/model.py R_LVLH_FROM_CAM (flight-software copy; the viewer does not import agent/):
# columns = camera axes in LVLH: x_c = -z, y_c = -x, z_c = +y
R_LVLH_FROM_CAM = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]).T


@dataclass(frozen=True)
class CameraSpec:
    """The pinhole of every spacecraft's camera (pixels of the image the viewer gets)."""

    width_px: float
    height_px: float
    focal_px: float
    range_m: float


@dataclass(frozen=True)
class SceneSpec:
    camera: CameraSpec | None = None
    image_ids: tuple[str, ...] = ()           # spacecraft whose debug frames come (camera views)
    cone: tuple[float, float] | None = None   # (half angle rad, range m) about body +x
    landmark_kind: str | None = None          # sensing kind whose Measurements carry landmark returns
    shapes: dict[str, dict[str, Any]] = field(default_factory=dict)
    accel_ref_mps2: float | None = None       # the largest acceleration limit, when there is one

    @classmethod
    def from_config(cls, cfg: dict[str, Any] | None) -> "SceneSpec":
        if not cfg:
            return cls()
        sensing = cfg.get("sensing") or {}
        kind = str(sensing.get("kind", ""))
        params = sensing.get("params") or {}
        ids = tuple(str(s["id"]) for s in cfg.get("spacecraft") or [])
        camera, image_ids = None, ()
        if kind in CAMERA_KINDS:
            c = cfg.get("camera") or {}
            nav = cfg.get("nav") or {}
            images = float(nav.get("debug_image_period_s") or 0.0) > 0.0
            d = int(nav.get("debug_image_downsample") or 4) if images else 1
            px = int(c.get("image_px", 1080))
            camera = CameraSpec(float(px // d), float(px // d), float(c.get("focal_px", 1000.0)) / d,
                                float(c.get("detection_range_m", 500.0)))
            image_ids = ids if images else ()
        cone = None
        landmarks = kind not in CAMERA_KINDS and kind in landmark_kinds()
        if landmarks:
            cone = (math.radians(float(params.get("fov_full_deg", 75.0))) / 2.0, float(params.get("range_m", 8.5)))
        shapes = {str(b["id"]): b["shape"] for b in cfg.get("body") or [] if isinstance(b, dict) and b.get("shape")}
        return cls(camera, image_ids, cone, kind if landmarks else None, shapes, accel_limit(cfg))


def accel_limit(cfg: dict[str, Any]) -> float | None:
    """The largest acceleration limit of the spacecraft (max_force_n / mass_kg, max_accel_mps2, or
    [actuator]), None when there is none worth scaling arrows by."""
    act = (cfg.get("actuator") or {}).get("max_accel_mps2")
    out = []
    for s in cfg.get("spacecraft") or []:
        if s.get("max_force_n") and s.get("mass_kg"):
            out.append(float(s["max_force_n"]) / float(s["mass_kg"]))
        elif s.get("max_accel_mps2"):
            out.append(float(s["max_accel_mps2"]))
        elif act:
            out.append(float(act))
    a = max(out) if out else None
    return a if a is not None and 0.0 < a < UNLIMITED_ACCEL_MPS2 else None


def display_lengths(pos_m: np.ndarray) -> dict[str, float]:
    """Sizes of the drawn helpers from the extent of the swarm (largest side of its bounding box)."""
    p = np.asarray(pos_m, float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    extent = max(float(np.ptp(p, axis=0).max()) if len(p) > 1 else 0.0, 1.0)
    return {"axes_m": 0.04 * extent, "frustum_m": 0.08 * extent, "thrust_m": 0.12 * extent, "world_axes_m": 0.05 * extent}


def cone_strips(half_angle_rad: float, range_m: float, n: int = 24) -> list[np.ndarray]:
    """The rim (at range, on the sphere of radius range_m) and four generators of a cone about +x."""
    a = np.linspace(0.0, 2.0 * math.pi, n + 1)
    x, r = range_m * math.cos(half_angle_rad), range_m * math.sin(half_angle_rad)
    rim = np.stack([np.full_like(a, x), r * np.cos(a), r * np.sin(a)], axis=1)
    gens = [np.array([[0.0, 0.0, 0.0], rim[i]]) for i in range(0, n, n // 4)]
    return [rim, *gens]


def shape_ellipsoids(shape: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray] | None:
    """(centres (K, 3), half sizes (K, 3)) in the body frame of a `[[body]].shape`."""
    if not shape:
        return None
    if shape.get("kind") == "ellipsoid":
        return np.zeros((1, 3)), np.asarray(shape["semi_axes_m"], float).reshape(1, 3)
    centres = np.asarray(shape.get("centers_m") or [], float).reshape(-1, 3)
    radii = np.asarray(shape.get("radii_m") or [], float).reshape(-1)
    if not len(centres) or len(centres) != len(radii):
        return None
    return centres, np.repeat(radii[:, None], 3, axis=1)


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, float)[..., [1, 2, 3, 0]]
