"""Hulls and contact (issue 27): every spacecraft and body has a hard body, and the plant records
when two of them touch or come closer than the scenario's keep-out distance.

Hulls: a spacecraft is a sphere of `[[spacecraft]] radius_m` (default `[contact].default_radius_m`,
DEFAULT_RADIUS_M = 0.5 m: a microsatellite about a metre across); a body is its `shape` (an
ellipsoid, or a union of spheres, in its own frame) or else a sphere of its `radius_m` (the same
default). `[contact] point_masses = true` declares the spacecraft and bodies points: no contact is
then looked for (a report says so), only the keep-out distance between centres.

Each step (the truth of step k): a pair is *in contact* when the hulls overlap (spheres: centre
distance < r_i + r_j; a spacecraft and an ellipsoid of semi-axes a: the spacecraft's centre inside
the ellipsoid grown by r, sum((x_b / (a + r))^2) < 1 in the body frame, a conservative stand-in
for the exact offset surface); *near* when the gap between hulls is under `[contact].keep_out_m`
(the same tests with every radius grown by keep_out_m). An Event `contact` is recorded when a pair
comes into contact, `near_miss` when it comes within the keep-out distance without touching; a pair
records again only after it has left that zone.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from swarmhil.plant.sensors import TREE_MIN_COUNT, pairs_within

if TYPE_CHECKING:  # (plant/config.py imports this module's ContactConfig)
    from swarmhil.plant.config import PlantConfig

DEFAULT_RADIUS_M = 0.5


class ContactConfig(BaseModel):
    """The `[contact]` table."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    default_radius_m: float = Field(DEFAULT_RADIUS_M, gt=0)  # hard-body radius of whatever gives none
    keep_out_m: float = Field(0.0, ge=0)                      # near miss: gap between hulls below this (0: off)
    point_masses: bool = False                                # no hulls: no contact is looked for


SMALL_SWARM = 12
"""Up to this many centres, `centre_d2` takes the (N, N, 3) differences (the fewest numpy calls);
above, one axis at a time (less memory traffic)."""


def centre_d2(pos_m: np.ndarray) -> np.ndarray:
    """(N, N) squared distances between centres: (x_i - x_j)^2 + (y_i - y_j)^2, then + (z_i - z_j)^2,
    the same float64 by either route (`SMALL_SWARM`)."""
    if len(pos_m) <= SMALL_SWARM:
        d = pos_m[:, None, :] - pos_m
        d *= d
        out = d[..., 0] + d[..., 1]
        out += d[..., 2]
        return out
    x, y, z = pos_m[:, 0], pos_m[:, 1], pos_m[:, 2]
    dx, dy, dz = x[:, None] - x, y[:, None] - y, z[:, None] - z
    dx *= dx
    dy *= dy
    dz *= dz
    dx += dy
    dx += dz
    return dx


@dataclass(frozen=True)
class CloseCentres:
    """The pairs (a, b), a < b, of a large swarm whose centres are within `reach` of each other (and maybe
    a few just beyond: plant/sensors.py `pairs_within`, a spatial index), with their squared distances
    computed as `centre_d2` computes them: what `centre_d2` and `reach2` decide for every pair that can
    touch, without the (N, N) matrices."""

    a: np.ndarray
    b: np.ndarray
    d2: np.ndarray

    @staticmethod
    def of(pos_m: np.ndarray, reach_m: float) -> "CloseCentres":
        a, b = pairs_within(pos_m, reach_m)
        d = pos_m[a] - pos_m[b]
        d *= d
        d2 = d[:, 0] + d[:, 1]
        d2 += d[:, 2]
        order = np.lexsort((b, a))  # (row-major, as np.nonzero of the matrix)
        return CloseCentres(a[order], b[order], d2[order])

    def hits(self, radius_m: np.ndarray, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The pairs closer than their reach r_a + r_b + margin_m (`reach2`'s sum, squared)."""
        hit = self.d2 < (radius_m[self.a] + radius_m[self.b] + margin_m) ** 2
        return self.a[hit], self.b[hit]


def reach2(radius_m: np.ndarray, margin_m: float) -> np.ndarray:
    """(N, N) squared reach (r_i + r_j + margin)^2 of two spheres grown by margin, upper triangle;
    -1 elsewhere (a pair counted once, nobody with itself): overlap when centre_d2 < reach2."""
    r = (radius_m[:, None] + radius_m[None, :] + margin_m) ** 2
    r[np.tril_indices(len(radius_m))] = -1.0
    return r


def _rotate_to_body(q_wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v for rows v (N, 3): frame vectors in body axes (q scalar-first, body -> frame)."""
    w, x, y, z = np.asarray(q_wxyz, dtype=float).tolist()  # (Python floats: numpy scalars' arithmetic, without their cost)
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return v @ r


def body_hits(pos_m: np.ndarray, radius_m: np.ndarray, body_pos_m: np.ndarray, body_q: np.ndarray,
              shape: Any, body_radius_m: float, margin_m: float) -> np.ndarray:
    """(N,) bool: spacecraft i's hull (grown by margin) meets the body's (`shape` None: a sphere)."""
    rel = pos_m - body_pos_m
    grow = radius_m + margin_m
    if shape is None:
        reach = grow + body_radius_m
        return np.einsum("ij,ij->i", rel, rel) < reach * reach
    xb = _rotate_to_body(np.asarray(body_q, float), rel)
    if shape.kind == "ellipsoid":
        axes = np.asarray(shape.semi_axes_m, float)[None, :] + grow[:, None]
        return np.sum((xb / axes) ** 2, axis=1) < 1.0
    centres, radii = np.asarray(shape.centers_m, float), np.asarray(shape.radii_m, float)
    d = xb[:, None, :] - centres[None, :, :]
    reach = radii[None, :] + grow[:, None]
    return np.any(np.einsum("ijk,ijk->ij", d, d) < reach * reach, axis=1)


@dataclass
class ContactMonitor:
    """Pairs in contact / within keep-out at the last step; `check` returns the new ones."""

    ids: list[str]
    radius_m: np.ndarray                # (N,) spacecraft hulls
    bodies: list[Any]                   # BodySpec of the non-agent bodies
    body_radius_m: dict[str, float]
    cfg: ContactConfig
    _contact: set[tuple[str, str]] = field(default_factory=set)
    _near: set[tuple[str, str]] = field(default_factory=set)
    contacts: list[dict[str, Any]] = field(default_factory=list)
    near_misses: list[dict[str, Any]] = field(default_factory=list)

    @staticmethod
    def of(sc: PlantConfig) -> "ContactMonitor":
        cfg = sc.contact or ContactConfig()
        r0 = 0.0 if cfg.point_masses else cfg.default_radius_m
        radii = np.array([r0 if cfg.point_masses or getattr(s, "radius_m", None) is None else s.radius_m
                          for s in sc.spacecraft], dtype=float)
        bodies = list(sc.bodies)
        body_r = {b.id: r0 if cfg.point_masses or getattr(b, "radius_m", None) is None else b.radius_m for b in bodies}
        return ContactMonitor(list(sc.ids), radii, bodies, body_r, cfg)

    def __post_init__(self) -> None:
        self._reach2_contact = reach2(self.radius_m, 0.0)
        self._reach2_near = reach2(self.radius_m, self.cfg.keep_out_m)

    def _pairs(self, pos_m: np.ndarray, d2: Any, body_truth: list[Any], near: bool) -> set[tuple[str, str]]:
        out: set[tuple[str, str]] = set()
        if isinstance(d2, CloseCentres):
            i, j = d2.hits(self.radius_m, self.cfg.keep_out_m if near else 0.0)
            out = {(self.ids[a], self.ids[b]) for a, b in zip(i.tolist(), j.tolist())}
        else:
            hit = d2 < (self._reach2_near if near else self._reach2_contact)
            if np.count_nonzero(hit):
                i, j = np.nonzero(hit)
                out = {(self.ids[a], self.ids[b]) for a, b in zip(i.tolist(), j.tolist())}
        margin = self.cfg.keep_out_m if near else 0.0
        for bt in body_truth:
            shape = None if self.cfg.point_masses else bt.spec.shape
            hit = body_hits(pos_m, self.radius_m, bt.position_m, bt.attitude_q, shape,
                            self.body_radius_m.get(bt.spec.id, self.cfg.default_radius_m), margin)
            out |= {(self.ids[k], bt.spec.id) for k in np.flatnonzero(hit).tolist()}
        return out

    def check(self, step: int, t_s: float, pos_m: np.ndarray, body_truth: list[Any]) -> list[tuple[str, str, str]]:
        """(kind "contact" | "near_miss", "a|b", detail) of the pairs that came into contact or within
        the keep-out distance at this step."""
        if len(pos_m) >= TREE_MIN_COUNT and np.isfinite(pos_m).all():  # a large swarm: the pairs near enough only
            d2: Any = CloseCentres.of(pos_m, 2.0 * float(self.radius_m.max(initial=0.0)) + self.cfg.keep_out_m)
        else:
            d2 = centre_d2(pos_m)
        contact = set() if self.cfg.point_masses else self._pairs(pos_m, d2, body_truth, False)
        near = self._pairs(pos_m, d2, body_truth, True) if self.cfg.keep_out_m > 0 else set()
        if not (contact or near or self._contact or self._near):
            return []
        out: list[tuple[str, str, str]] = []
        where = {s: pos_m[i] for i, s in enumerate(self.ids)} | {bt.spec.id: bt.position_m for bt in body_truth}
        for kind, now, before, log in (("contact", contact, self._contact, self.contacts),
                                       ("near_miss", near - contact, self._near, self.near_misses)):
            for a, b in sorted(now - before):
                d = float(np.linalg.norm(where[a] - where[b]))
                log.append({"step": step, "t_s": t_s, "pair": [a, b], "distance_m": d})
                out.append((kind, f"{a}|{b}", f"centres {d:.4g} m apart at t = {t_s:g} s"))
        self._contact, self._near = contact, near
        return out

    def summary(self) -> dict[str, Any]:
        return {"point_masses": self.cfg.point_masses, "keep_out_m": self.cfg.keep_out_m,
                "contacts": len(self.contacts), "near_misses": len(self.near_misses),
                "first_contact": self.contacts[0] if self.contacts else None,
                "first_near_miss": self.near_misses[0] if self.near_misses else None}
