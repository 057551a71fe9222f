"""The one interface of the navigation estimators (issue 4) and what they output.

A navigator turns the blobs of successive camera frames into tracks. Each track carries the
state of the neighbour k relative to this spacecraft j (k minus j): LVLH position and velocity
(x radial, y along-track, z cross-track) and ROE in metres, a*(da, dl, dex, dey, dix, diy), with
the covariance of the ROE where the estimator has one. Paper 002's controller uses the ROE of the
observer relative to the neighbour (NOTES-002): that is minus `roe_m`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from swarmhil.agent.blob.blobs import Blobs


@dataclass
class Track:
    track_id: str
    roe_m: np.ndarray  # (6,)
    position_m: np.ndarray  # (3,) LVLH, neighbour - observer
    velocity_mps: np.ndarray  # (3,)
    covariance_m2: np.ndarray | None = None  # (6, 6) of roe_m
    age_steps: int = 0  # frames since the track was created
    hits: int = 1  # frames in which a blob updated it
    blob_index: int = -1  # blob used in the latest frame, -1 if none
    quiet_covariance_m2: np.ndarray | None = None  # (6, 6) of the IMM's quiet model (agent/nav/ekf.py), None without IMM


class Navigator(Protocol):
    name: str

    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None) -> list[Track]:
        """Take one frame's blobs at time t_s (reference mean argument of latitude u_rad) and the
        observer's own LVLH acceleration held since the previous frame; return confirmed tracks."""
        ...


def observation_arrays(tracks: list[Track]) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Tracks -> (ids, rel_position_m (N, 3), rel_velocity_mps (N, 3)) for agent.controller.Observation."""
    ids = [t.track_id for t in tracks]
    pos = np.array([t.position_m for t in tracks]).reshape(-1, 3)
    vel = np.array([t.velocity_mps for t in tracks]).reshape(-1, 3)
    return ids, pos, vel


def guarded(fn: Callable[..., Any], *args: Any) -> Any:
    """fn(*args), or the exception it raised (the batch updates of several navigators: each one's
    fault is handed back in its place)."""
    try:
        return fn(*args)
    except Exception as e:  # noqa: BLE001 - handed to the caller, which handles it per navigator
        return e


def update_together(navs: list[Any], t_s: float, u_rad: float, blobs: list[Blobs], own_accel_mps2: list[np.ndarray | None],
                    frame_arrays: Callable[..., Any], commit: Callable[..., list[Any]]) -> list[Any]:
    """The frame of several navigators of one class at once (their `update_many`): plan =
    frame_arrays(navs, t_s, u_rad, blobs, own_accel_mps2) computes everything without writing, then
    commit(navs, t_s, u_rad, blobs, plan) writes each navigator's part and returns its tracks or the
    exception of its part. Navigators of different settings (`batch_key`), or a plan that raises,
    run their own `update` one by one (each fault its navigator's)."""
    if len({nav.batch_key for nav in navs}) > 1:
        return [guarded(nav.update, t_s, u_rad, b, a) for nav, b, a in zip(navs, blobs, own_accel_mps2)]
    try:
        plan = frame_arrays(navs, t_s, u_rad, blobs, own_accel_mps2)
    except Exception:  # noqa: BLE001 - nothing written yet: each its own update, which raises alone
        return [guarded(nav.update, t_s, u_rad, b, a) for nav, b, a in zip(navs, blobs, own_accel_mps2)]
    return commit(navs, t_s, u_rad, blobs, plan)
