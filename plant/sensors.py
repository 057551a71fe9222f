"""Sensor stimuli the plant computes from truth (DESIGN.md: plant owns stimulus generation).

`rel` stimulus (issue 2): the ideal relative LVLH state of every spacecraft the observer's camera
could see: range <= detection range and inside the square field of view around the boresight,
which points along-track (+y LVLH, paper 002 section 3.1 / 5).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraGeometry:
    detection_range_m: float = 500.0
    image_px: int = 1080
    focal_px: float = 1000.0
    boresight: tuple[float, float, float] = (0.0, 1.0, 0.0)  # LVLH, along-track

    @property
    def tan_half_fov(self) -> float:
        """tan of the half field of view: (image_px / 2) / f = 0.54 -> 28.37 deg for the paper's camera."""
        return (self.image_px / 2.0) / self.focal_px


def visibility_matrix(pos_m: np.ndarray, cam: CameraGeometry, alive: np.ndarray | None = None) -> np.ndarray:
    """V[j, k] = True when k is within range and inside j's square FOV (boresight +y LVLH).

    For boresight +y: rel = r_k - r_j must have rel_y > 0, |rel_x| <= tan * rel_y,
    |rel_z| <= tan * rel_y and |rel| <= detection range. Dead spacecraft still reflect light, so
    they stay visible; a dead observer sees nothing (its camera is off).
    """
    vis = np.empty((len(pos_m), len(pos_m)), dtype=bool)
    in_view(pos_m[None, :, :] - pos_m[:, None, :], cam, vis)
    vis.ravel()[:: vis.shape[0] + 1] = False  # nobody sees itself (np.fill_diagonal, without its Python)
    if alive is not None:
        vis &= alive[:, None]
    return vis


def in_view(rel: np.ndarray, cam: CameraGeometry, out: np.ndarray) -> np.ndarray:
    """out[..., j, k] = r_k - r_j (rel[..., j, k, :]) is within range and inside j's square FOV
    (`visibility_matrix`'s rule, for any leading axes: dashboards/metrics.py evaluates many steps
    at once)."""
    if cam.boresight != (0.0, 1.0, 0.0):
        raise NotImplementedError("only the along-track (+y) boresight of paper 002 is modelled")
    ahead = rel[..., 1]
    lim = cam.tan_half_fov * ahead
    np.greater(ahead, 0.0, out=out)
    side = np.abs(rel[..., ::2])  # |x|, |z|: both <= lim is max(|x|, |z|) <= lim (np.maximum keeps a NaN: False)
    out &= np.maximum(side[..., 0], side[..., 1]) <= lim
    out &= np.einsum("...i,...i->...", rel, rel) <= cam.detection_range_m**2
    return out


def weakly_connected(vis: np.ndarray) -> bool:
    """True when the digraph vis (N x N, bool) is weakly connected (one component, N >= 1).

    Breadth-first over the undirected graph with numpy (exact, like scipy's connected_components,
    which it replaced so that a process loading a scenario does not import scipy.sparse, issue 16).
    """
    adj = np.asarray(vis, dtype=bool)
    n = adj.shape[0]
    if n == 0:
        return False
    adj = adj | adj.T
    reach = np.zeros(n, dtype=bool)
    reach[0] = True
    frontier = reach.copy()
    while frontier.any():
        new = adj[frontier].any(axis=0) & ~reach
        reach |= new
        frontier = new
    return bool(reach.all())
