"""Formation measures of paper 001: eq. 16 and a geometric hexagon test (NOTES-001 trap 2).

Pure functions of an (N, 3) array of positions in metres (CW frame).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def hexagon_vertices(side_m: float, phase_deg: float = 30.0, x_shift_m: float = 0.0) -> np.ndarray:
    """The desired hexagon (Fig. 1): vertices in the yz-plane at angles phase + 60 k from +y."""
    ang = np.deg2rad(phase_deg + 60.0 * np.arange(6))
    return np.column_stack([np.full(6, x_shift_m), side_m * np.cos(ang), side_m * np.sin(ang)])


def _distances(pos: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    return d


def mean_relative_error(pos_m: np.ndarray, side_m: float, neighbours: int = 2) -> float:
    """Eq. 16: sum_i sum_{j in N_i} |l - r_ij| / l / (2N), N_i the two closest agents of i."""
    d = _distances(np.asarray(pos_m, dtype=float))
    near = np.sort(d, axis=1)[:, :neighbours]
    return float(np.sum(np.abs(side_m - near) / side_m) / (neighbours * d.shape[0]))


@dataclass(frozen=True)
class HexagonCheck:
    is_hexagon: bool
    side_min_m: float
    side_max_m: float
    angle_min_deg: float
    angle_max_deg: float
    thickness_m: float  # largest distance from the best-fit plane
    normal_x: float  # |x component| of the plane's unit normal (1 = parallel to yz)
    centre_m: np.ndarray
    phase_deg: float  # vertex angle from +y in the yz-plane, mod 60
    ring: bool  # the two-nearest-neighbour graph is one 6-cycle
    eq16: float


def check_hexagon(pos_m: np.ndarray, side_m: float, side_tol: float = 0.1, angle_tol_deg: float = 10.0,
                  thickness_tol_m: float = 0.5) -> HexagonCheck:
    """Is this a regular hexagon of side l? Judged by geometry: one ring, sides, angles, planarity."""
    pos = np.asarray(pos_m, dtype=float)
    n = pos.shape[0]
    d = _distances(pos)
    nn = np.argsort(d, axis=1)[:, :2]
    adj = np.zeros((n, n), dtype=bool)
    adj[np.arange(n)[:, None], nn] = True
    mutual = adj & adj.T
    ring = bool(np.all(mutual.sum(axis=1) == 2)) and _one_cycle(mutual)
    sides = d[np.arange(n)[:, None], nn]
    angles = []
    for i in range(n):
        a, b = pos[nn[i, 0]] - pos[i], pos[nn[i, 1]] - pos[i]
        angles.append(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))
    centre = pos.mean(axis=0)
    _u, _s, vt = np.linalg.svd(pos - centre)
    normal = vt[-1]
    thickness = float(np.max(np.abs((pos - centre) @ normal)))
    rel = pos - centre
    phase = _circular_mean_mod60(np.degrees(np.arctan2(rel[:, 2], rel[:, 1])))
    ok = (
        n == 6
        and ring
        and float(np.max(np.abs(sides / side_m - 1.0))) <= side_tol
        and float(np.max(np.abs(np.array(angles) - 120.0))) <= angle_tol_deg
        and thickness <= thickness_tol_m
    )
    return HexagonCheck(
        is_hexagon=bool(ok),
        side_min_m=float(sides.min()),
        side_max_m=float(sides.max()),
        angle_min_deg=float(min(angles)),
        angle_max_deg=float(max(angles)),
        thickness_m=thickness,
        normal_x=float(abs(normal[0])),
        centre_m=centre,
        phase_deg=phase,
        ring=ring,
        eq16=mean_relative_error(pos, side_m),
    )


def _one_cycle(adj: np.ndarray) -> bool:
    seen, stack = {0}, [0]
    while stack:
        i = stack.pop()
        for j in np.flatnonzero(adj[i]):
            if int(j) not in seen:
                seen.add(int(j))
                stack.append(int(j))
    return len(seen) == adj.shape[0]


def _circular_mean_mod60(angles_deg: np.ndarray) -> float:
    """Mean of angles taken modulo 60 deg (a hexagon's phase), in [0, 60)."""
    z = np.exp(1j * np.deg2rad(np.asarray(angles_deg) * 6.0))
    return float(np.degrees(np.angle(z.mean())) / 6.0 % 60.0)


def structure_name(pos_m: np.ndarray, side_m: float, bond_factor: float = 1.3) -> str:
    """A short name for what formed (NOTES-001 trap 1): bonds are pairs closer than bond_factor * l.

    "6-ring", "5-ring+1" (a ring of five with a dangling agent), "chain", "branched tree",
    "fragments" (not connected), "multi-ring"; prefixed "3-D " when not planar within 0.5 m.
    """
    pos = np.asarray(pos_m, dtype=float)
    n = pos.shape[0]
    d = _distances(pos)
    adj = d < bond_factor * side_m
    edges = int(adj.sum()) // 2
    centre = pos.mean(axis=0)
    thickness = float(np.max(np.abs((pos - centre) @ np.linalg.svd(pos - centre)[2][-1]))) if n >= 3 else 0.0
    prefix = "3-D " if thickness > 0.5 else ""
    if not _one_cycle(adj):
        return prefix + "fragments"
    cycles = edges - n + 1
    if cycles == 0:
        return prefix + ("chain" if adj.sum(axis=1).max() <= 2 else "branched tree")
    if cycles > 1:
        return prefix + "multi-ring"
    alive = np.ones(n, dtype=bool)
    while True:  # prune leaves: what is left is the ring
        deg = (adj & alive[None, :] & alive[:, None]).sum(axis=1)
        leaves = alive & (deg <= 1)
        if not leaves.any():
            break
        alive &= ~leaves
    ring = int(alive.sum())
    return prefix + (f"{ring}-ring" if ring == n else f"{ring}-ring+{n - ring}")
