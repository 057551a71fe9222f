"""The target's ACSB envelope (Table 2, signs and square roots restored) and the servicers' slots
(Table 1), as configuration data.

NOTES-003: the extracted Table 2 lost its minus signs and its √ ("15 2" is 15√2 m). The structure is
symmetric: the core cabin along +x, the transporter along -x, payload cabins I and II at +y and -y,
solar arrays I and II at +z and -z. Centres d_Cg are in the target's frame (attitude ignored,
Assumption 2), so q_Cg(t) = q_TL(t) + d_Cg in the leader's LVLH (§5).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SQRT2 = float(np.sqrt(2.0))


@dataclass(frozen=True)
class Sphere:
    part: str
    centre_m: tuple[float, float, float]
    radius_m: float


def _spheres() -> tuple[Sphere, ...]:
    rows: list[Sphere] = [Sphere("core cabin", (0.0, 0.0, 0.0), 5 * SQRT2)]
    rows += [Sphere("core cabin", (x, 0.0, 0.0), 15 * SQRT2) for x in (20.0, 50.0, 80.0)]
    rows += [Sphere("transporter", (-x, 0.0, 0.0), 10 * SQRT2) for x in (15.0, 35.0, 55.0)]
    for name, sign in (("payload cabin I", 1.0), ("payload cabin II", -1.0)):
        rows.append(Sphere(name, (0.0, sign * 10.0, 0.0), 5 * SQRT2))
        rows += [Sphere(name, (0.0, sign * y, 0.0), 10 * SQRT2) for y in (25.0, 45.0)]
    for name, sign in (("solar array I", 1.0), ("solar array II", -1.0)):
        rows += [Sphere(name, (0.0, 0.0, sign * z), 5 * SQRT2) for z in (10.0, 20.0, 30.0, 40.0)]
    return tuple(rows)


ACSB_SPHERES: tuple[Sphere, ...] = _spheres()
"""Table 2: 21 circumscribed spheres (d_Cg, r_g)."""


def sphere_arrays(spheres: tuple[Sphere, ...] = ACSB_SPHERES) -> tuple[np.ndarray, np.ndarray]:
    """(G, 3) centres d_Cg and (G,) radii r_g, in m."""
    return (np.array([s.centre_m for s in spheres], dtype=float),
            np.array([s.radius_m for s in spheres], dtype=float))


SLOT_OFFSETS_M: np.ndarray = np.array([
    [50.0, 50.0, -50.0],
    [50.0, -50.0, 50.0],
    [-50.0, 50.0, 50.0],
    [50.0, -50.0, -50.0],
    [-50.0, 50.0, -50.0],
    [-50.0, -50.0, 50.0],
])
"""Table 1's desired q_Ti,d, all printed (50, 50, 50): corners (±50, ±50, ±50) of the target.
Choice: the six corners off the approach diagonal (+,+,+)/(-,-,-) along which the target comes in
from q_TL(0) = (900, 500, 500) m, so the target's own approach never sweeps through a slot."""


def slots_in_leader_frame(q_tl_des_m: np.ndarray, offsets_m: np.ndarray = SLOT_OFFSETS_M) -> np.ndarray:
    """Desired q_Li,d = q_TL,d + q_Ti,d (eq. 1 with q_TL the target relative to the leader), (N, 3)."""
    return np.asarray(q_tl_des_m, dtype=float)[None, :] + np.asarray(offsets_m, dtype=float)
