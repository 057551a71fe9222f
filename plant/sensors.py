"""Sensor stimuli the plant computes from truth (DESIGN.md: plant owns stimulus generation).

`rel` stimulus (issue 2): the ideal relative LVLH state of every spacecraft the observer's camera
could see: range <= detection range and inside the square field of view around the boresight,
which points along-track (+y LVLH, paper 002 section 3.1 / 5).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


ALONG_TRACK = (0.0, 1.0, 0.0)


class VisibilityRule(Protocol):
    """What the rule reads of a camera: CameraGeometry (a scenario's [camera]) or the viewer's
    CameraRule (dashboards/rerun_bridge.py: a recording's range and tan of the half FOV)."""

    @property
    def detection_range_m(self) -> float: ...

    @property
    def tan_half_fov(self) -> float: ...


@dataclass(frozen=True)
class CameraGeometry:
    detection_range_m: float = 500.0
    image_px: int = 1080
    focal_px: float = 1000.0
    boresight: tuple[float, float, float] = ALONG_TRACK  # LVLH, along-track

    def __post_init__(self) -> None:
        if tuple(self.boresight) != ALONG_TRACK:
            raise NotImplementedError("only the along-track (+y) boresight of paper 002 is modelled")

    @property
    def tan_half_fov(self) -> float:
        """tan of the half field of view: (image_px / 2) / f = 0.54 -> 28.37 deg for the paper's camera."""
        return (self.image_px / 2.0) / self.focal_px


def visibility_matrix(pos_m: np.ndarray, cam: VisibilityRule, alive: np.ndarray | None = None) -> np.ndarray:
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


TREE_MIN_COUNT = 64
"""From this many spacecraft, `visible_pairs` finds the candidate pairs with a spatial index (a k-d
tree over the positions, rebuilt per call); below it, the (N, N) matrix costs less than the tree."""

RANGE_PAD = 1e-9
"""Relative margin of a spatial-index query radius over the exact test's radius, so that a pair the
exact test keeps by a tie at its edge is always among the candidates (the tree's distance is rounded
its own way)."""


def pairs_within(pos_m: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Candidate pairs (a, b), a < b, among the rows of pos_m (N, 3, finite) whose centres may be within
    `radius_m`: every pair whose distance is <= radius_m, and possibly a few just beyond it (the query
    radius is padded by `RANGE_PAD`). A k-d tree over the positions (scipy's cKDTree, built here):
    O(N log N + pairs) instead of the N^2 differences. Callers apply their exact test to the candidates."""
    from scipy.spatial import cKDTree  # (on use: the viewer and reports that read this module need no tree)

    if len(pos_m) < 2:
        none = np.zeros(0, dtype=np.int64)
        return none, none
    ab = cKDTree(pos_m).query_pairs(radius_m * (1.0 + RANGE_PAD) + RANGE_PAD, output_type="ndarray")
    return ab[:, 0].astype(np.int64), ab[:, 1].astype(np.int64)


def visible_pairs(pos_m: np.ndarray, cam: VisibilityRule, alive: np.ndarray | None = None,
                  tree: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(j, k) of every pair where j sees k: `visibility_matrix(pos_m, cam, alive).nonzero()`, the same
    pairs in the same (row-major) order, without the (N, N) matrix when the swarm is large.

    `tree` None: the spatial index from `TREE_MIN_COUNT` spacecraft (True / False force it). With the
    index, the candidates are the pairs within the detection range (`pairs_within`, both directions),
    and each is kept by the same `in_view` test of the same difference r_k - r_j as the matrix's, so
    the set is the matrix's exactly, ties at the range and at the field-of-view edges included
    (tests/test_visible_pairs.py). Positions that are not all finite take the matrix."""
    n = len(pos_m)
    if not (n >= TREE_MIN_COUNT if tree is None else tree) or not np.isfinite(pos_m).all():
        return visibility_matrix(pos_m, cam, alive).nonzero()
    a, b = pairs_within(pos_m, cam.detection_range_m)
    j, k = np.concatenate((a, b)), np.concatenate((b, a))
    if alive is not None:  # a dead observer sees nothing
        keep = np.asarray(alive, dtype=bool)[j]
        j, k = j[keep], k[keep]
    seen = in_view(pos_m[k] - pos_m[j], cam, np.empty(len(j), dtype=bool))
    j, k = j[seen], k[seen]
    order = np.lexsort((k, j))
    return j[order], k[order]


def weakly_connected_pairs(n: int, j: np.ndarray, k: np.ndarray) -> bool:
    """True when the digraph on n nodes with edges j -> k is weakly connected (n >= 1): `weakly_connected`
    of the matrix the pairs come from, by scipy's sparse components (no (N, N) matrix)."""
    from scipy.sparse import coo_matrix  # (on use, as pairs_within)
    from scipy.sparse.csgraph import connected_components

    if n < 1:
        return False
    g = coo_matrix((np.ones(len(j), dtype=np.int8), (j, k)), shape=(n, n)).tocsr()
    return int(connected_components(g, directed=True, connection="weak", return_labels=False)) == 1


def visibility_series(position_m: np.ndarray, cam: VisibilityRule, alive: np.ndarray | None = None) -> np.ndarray:
    """(T, N, N) bool: V[t, j, k] when j sees k at step t (`visibility_matrix` of each step, for many
    steps per numpy call: the same comparisons). position_m (T, N, 3), alive (T, N). The reports
    (dashboards/metrics.py) and the viewer (dashboards/rerun_bridge.py) use it."""
    T, N, _ = position_m.shape
    out = np.empty((T, N, N), dtype=bool)
    for t0 in range(0, T, 256):
        p = position_m[t0:t0 + 256]
        in_view(p[:, None, :, :] - p[:, :, None, :], cam, out[t0:t0 + 256])
    out[:, np.arange(N), np.arange(N)] = False
    if alive is not None:
        out &= np.asarray(alive, dtype=bool)[:, :, None]
    return out


def in_view(rel: np.ndarray, cam: VisibilityRule, out: np.ndarray) -> np.ndarray:
    """out[..., j, k] = r_k - r_j (rel[..., j, k, :]) is within range and inside j's square FOV about
    +y LVLH (paper 002 sec. 3.1, 5): the camera visibility rule, written once (for any leading axes)."""
    ahead = rel[..., 1]
    lim = cam.tan_half_fov * ahead
    np.greater(ahead, 0.0, out=out)
    side = np.abs(rel[..., ::2])  # |x|, |z|: both <= lim is max(|x|, |z|) <= lim (np.maximum keeps a NaN: False)
    out &= np.maximum(side[..., 0], side[..., 1]) <= lim
    out &= np.einsum("...i,...i->...", rel, rel) <= cam.detection_range_m**2
    return out


def weak_components(vis: np.ndarray, nodes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(n_components (T,), labels (T, N)) of the weakly connected components of each step's digraph
    vis (T, N, N), written once: the scenario check (`weakly_connected`), the reports and the viewer.

    `nodes` (T, N) bool: count the components of the subgraph of those nodes only (the viewer: the
    alive spacecraft); the others get label -1. Default: every node (the reports: a dead spacecraft
    is still seen). All steps at once (issue 16: scipy per step was most of a campaign run's metrics
    time): every node takes the smallest index of its undirected neighbourhood until nothing
    changes, so each ends with the smallest node index of its component; components are numbered
    in order of that index, which is scipy's connected_components numbering (tests/test_metrics.py).
    """
    T, N, _ = vis.shape
    if T == 0 or N == 0:
        return np.zeros(T, dtype=int), np.zeros((T, N), dtype=int)
    adj = np.asarray(vis, dtype=bool)
    adj = adj | adj.transpose(0, 2, 1)
    if nodes is not None:
        keep = np.asarray(nodes, dtype=bool)
        adj = adj & keep[:, :, None] & keep[:, None, :]
    lab = np.broadcast_to(np.arange(N), (T, N)).copy()
    while True:
        new = np.minimum(lab, np.where(adj, lab[:, None, :], N).min(axis=2))
        if np.array_equal(new, lab):
            break
        lab = new
    is_root = lab == np.arange(N)
    if nodes is not None:
        is_root &= keep
    rank = np.cumsum(is_root, axis=1) - 1
    labels = np.take_along_axis(rank, lab, axis=1).astype(int)
    if nodes is not None:
        labels[~keep] = -1
    return is_root.sum(axis=1).astype(int), labels


def weakly_connected(vis: np.ndarray) -> bool:
    """True when the digraph vis (N x N, bool) is weakly connected (one component, N >= 1)."""
    return bool(weak_components(np.asarray(vis, dtype=bool)[None])[0][0] == 1)
