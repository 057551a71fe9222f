"""Navigation from camera blobs (issue 4): paper 002's rough navigation and an EKF on relative ROE.

Both implement `Navigator.update(t_s, u_rad, blobs, own_accel_mps2) -> list[Track]`; choose one per
scenario with `make_navigator("rough" | "ekf", ...)`.
"""
from __future__ import annotations

from typing import Any

from swarmhil.agent.camera.model import Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav.base import Navigator, Track, observation_arrays
from swarmhil.agent.nav.ekf import EkfConfig, EkfNavigator
from swarmhil.agent.nav.rough import RoughNavigator


def make_navigator(kind: str, camera: Camera, shape: SpacecraftShape, a_m: float, n_radps: float, params: dict[str, Any] | None = None) -> Navigator:
    params = dict(params or {})
    if kind == "rough":
        return RoughNavigator(camera, shape, a_m, n_radps, **params)
    if kind == "ekf":
        return EkfNavigator(camera, shape, a_m, n_radps, EkfConfig(**params))
    raise ValueError(f"unknown navigator {kind!r}; known: ['ekf', 'rough']")


__all__ = ["EkfConfig", "EkfNavigator", "Navigator", "RoughNavigator", "Track", "make_navigator", "observation_arrays"]
