"""Paper 000's contract: what the plant's sensing kind and the capture flight software share.

Imports nothing of the project but `bus` (here: nothing at all); numpy only. Read by
missions/p000_capture/sense.py (the sensor, on the truth), missions/p000_capture/fsw/ (the flight
software), and the paper's report and seeds (missions/p000_capture/report/, missions/p000_capture/seeds.py).
docs/architecture.md "Mission rooms (issue 25)".

**Measurement names** (paper 000 §2.2, §3.2.2): the plant sends one `swarmhil.v1.Measurements` per
spacecraft and step; the agent reads the named arrays as `Observation.extra[name]`:

    p000_q_body_to_lvlh   (4,)   own attitude, scalar first, body -> CW (LVLH) frame
    p000_omega_body_radps (3,)   own body rate, body axes
    p000_position_m       (3,)   own position in the CW frame centred on the target's initial position
    p000_velocity_mps     (3,)   own velocity in that frame
    p000_landmarks_body_m (K, 3) landmark returns in the body (sensor) frame; may hold outliers
    p000_landmark_ids     (K,)   landmark ids, -1 for returns that are not a landmark (outliers)
    p000_surface_rel_m    (3,)   agent -> closest point of the true target surface, CW frame, present
                                 only within R_h (proximity sensing)

Neighbours' relative states come in the message's neighbour rows (Observation.rel_*).

**Geometry** (pure functions of numpy arrays): an ellipsoid is (centre c, shape matrix M) with
surface (x−c)ᵀM(x−c) = 1 and M = R diag(a⁻²) Rᵀ; R's columns are the principal axes in LVLH, a the
semi-axes. The plant uses it for the true surface (landmark set, proximity return), the flight
software for its estimate (fit, closest point, buffer slot of eq. 14 in
missions/p000_capture/fsw/ellipsoid.py), the report for the signed distance to the true surface. `dcm`: a scalar-first quaternion's rotation
matrix (the plant's landmarks, the report's target axes).

**Parameter model** `CaptureParams` (the mission's numbers: paper 000 Table 1 and §4, plus the choices
the paper leaves open, docs/paper000.md): the flight software flies with it, the report reads the
radii and limits a run used from it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

CONTROLLER = "p000-capture"
"""The controller the flight software registers and the report looks for."""
SENSING_KIND = "p000-landmarks"
"""The plant's sensing kind of this room (sense.py), which the viewer draws as a sensor cone."""

PREFIX = "p000_"
"""The prefix of every measurement name of paper 000."""
Q_BODY_TO_LVLH = PREFIX + "q_body_to_lvlh"
OMEGA_BODY_RADPS = PREFIX + "omega_body_radps"
POSITION_M = PREFIX + "position_m"
VELOCITY_MPS = PREFIX + "velocity_mps"
LANDMARKS_BODY_M = PREFIX + "landmarks_body_m"
LANDMARK_IDS = PREFIX + "landmark_ids"
SURFACE_REL_M = PREFIX + "surface_rel_m"


@dataclass(frozen=True)
class Ellipsoid:
    """Centre c, principal axes R (columns, LVLH) and semi-axes a: M = R diag(a⁻²) Rᵀ."""

    centre_m: np.ndarray      # (3,) LVLH
    rotation: np.ndarray      # (3, 3) principal axes (columns) in LVLH
    semi_axes_m: np.ndarray   # (3,)

    @property
    def shape_matrix(self) -> np.ndarray:
        return self.rotation @ np.diag(self.semi_axes_m ** -2.0) @ self.rotation.T

    @classmethod
    def from_shape_matrix(cls, centre_m: np.ndarray, shape: np.ndarray) -> "Ellipsoid":
        """Principal axes from M; raises if M is not positive definite (not an ellipsoid)."""
        sym = 0.5 * (shape + shape.T)
        eig, vec = np.linalg.eigh(sym)
        if eig[0] <= 0.0:
            raise ValueError(f"shape matrix is not positive definite: eigenvalues {eig}")
        return cls(np.asarray(centre_m, dtype=float), vec, eig ** -0.5)


def closest_point_principal(p: np.ndarray, a: np.ndarray, iters: int = 100) -> np.ndarray:
    """Closest point on x²/a₀²+y²/a₁²+z²/a₂² = 1 to p, all in the principal frame.

    The stationary points are x_k = a_k² p_k/(a_k² + t). The root of
    f(t) = Σ(a_k p_k/(a_k²+t))² − 1 = 0 on t > −min a_k² is the answer for a general point, but when p
    has a zero component along an axis whose t = −a_k² pole is reached (an interior point on a
    principal plane), the answer is off that branch: x_k = ±a_k √(1 − Σ_{j≠k} (x_j/a_j)²) with
    x_j = a_j² p_j/(a_j² − a_k²) (NOTES-000: the closest point to (3.5, 0, 0) on (4, 1.3, 1) is not
    the tip). Every candidate is computed and the nearest kept.

    The root by Newton's method on φ(t) = S(t)^-½ − 1, S = f + 1: φ is increasing and concave on
    t > −min a_k² (S^-½ is the power mean of exponent −2 of the (a_k² + t)/(a_k |p_k|), affine in t),
    so from a start with φ ≤ 0 — t₀ = max_k (a_k |p_k| − a_k²), where the k-th term alone is 1 — the
    iterates climb monotonically to the root without overshooting, and near a pole, where φ is
    almost linear, in a step or two (typically 3–6 steps; bisection took ~45).
    """
    pl = [float(v) for v in np.asarray(p, dtype=float).reshape(3)]
    al = [float(v) for v in np.asarray(a, dtype=float).reshape(3)]
    return np.array(_closest_point(pl, al, iters))


def _closest_point(pl: list[float], al: list[float], iters: int) -> list[float]:
    """`closest_point_principal` in Python floats: point pl, semi-axes al (3 floats each) -> the
    closest point's 3 coordinates (the one body of the scalar and the row-by-row closest point)."""
    p0, p1, p2 = pl
    a0, a1, a2 = al
    y0, y1, y2 = abs(p0), abs(p1), abs(p2)
    aa0, aa1, aa2 = a0 * a0, a1 * a1, a2 * a2
    tiny = 1e-12 * max(a0, a1, a2)
    m = 0  # the first smallest a_k², as min() keeps it
    if aa1 < aa0:
        m = 1
    if aa2 < (aa1 if m == 1 else aa0):
        m = 2
    aam = (aa0, aa1, aa2)[m]
    x = None

    # t = u − a_m² with a_m the smallest axis: a_k² + t = (a_k² − a_m²) + u keeps its digits near
    # the pole u → 0 (an interior point close to the plane of the smallest axis)
    ay0, ay1, ay2 = a0 * y0, a1 * y1, a2 * y2
    d0, d1, d2 = aa0 - aam, aa1 - aam, aa2 - aam
    u = 1e-15 * max(1.0, aam)
    if (ay0 / (d0 + u)) ** 2 + (ay1 / (d1 + u)) ** 2 + (ay2 / (d2 + u)) ** 2 > 1.0:
        u = max(u, ay0 - d0, ay1 - d1, ay2 - d2)
        for _ in range(iters):  # python floats: a handful of steps
            r0, r1, r2 = ay0 / (d0 + u), ay1 / (d1 + u), ay2 / (d2 + u)
            s = r0 * r0 + r1 * r1 + r2 * r2
            if s <= 1.0:
                break
            slope = r0 * r0 / (d0 + u) + r1 * r1 / (d1 + u) + r2 * r2 / (d2 + u)  # −S′/2
            u_next = u + s * (math.sqrt(s) - 1.0) / slope  # Newton on S^-1/2 − 1
            if u_next <= u:
                break
            u = u_next
        x = [aa0 * y0 / (d0 + u), aa1 * y1 / (d1 + u), aa2 * y2 / (d2 + u)]
        if y0 > tiny and y1 > tiny and y2 > tiny:  # no zero coordinate: the only candidate
            return [-x[0] if p0 < 0.0 else x[0], -x[1] if p1 < 0.0 else x[1], -x[2] if p2 < 0.0 else x[2]]
    return _off_branch(pl, al, m, tiny, x)


def _off_branch(pl: list[float], al: list[float], m: int, tiny: float, root: list[float] | None) -> list[float]:
    """`_closest_point` with a zero coordinate or no root to find: the candidates off the general
    branch (and `root`, the general branch's point when found), the nearest kept."""
    y = [abs(v) for v in pl]
    aa = [v * v for v in al]
    cands: list[list[float]] = [] if root is None else [root]
    for k in range(3):
        if y[k] > tiny:
            continue
        others = [j for j in range(3) if j != k]
        if any(abs(aa[j] - aa[k]) < 1e-15 for j in others):
            continue
        x = [0.0, 0.0, 0.0]
        for j in others:
            x[j] = aa[j] * y[j] / (aa[j] - aa[k])
        rest = 1.0 - sum((x[j] / al[j]) ** 2 for j in others)
        if rest >= 0.0:
            x[k] = al[k] * math.sqrt(rest)
            cands.append(x)
    if not cands:  # p at the centre of a sphere-like degenerate case: the smallest-axis tip
        x = [0.0, 0.0, 0.0]
        x[m] = al[m]
        cands.append(x)
    best = min(cands, key=lambda c: math.dist(c, y)) if len(cands) > 1 else cands[0]
    return [-v if q < 0.0 else v for v, q in zip(best, pl)]


def surface_frame(ell: Ellipsoid, p_m: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(signed distance, closest point x_s, outward normal n) in one closest-point solve."""
    p = np.asarray(p_m, dtype=float)
    local = ell.rotation.T @ (p - ell.centre_m)
    x = closest_point_principal(local, ell.semi_axes_m)
    n = x / ell.semi_axes_m ** 2
    n = n / math.sqrt(dot3(n, n))
    gap = local - x
    d = math.sqrt(dot3(gap, gap))
    scaled = local / ell.semi_axes_m
    inside = dot3(scaled, scaled) < 1.0
    return (-d if inside else d), ell.centre_m + ell.rotation @ x, ell.rotation @ n


def dot3(a: np.ndarray, b: np.ndarray) -> float:
    """a · b of two 3-vectors as (a₀b₀ + a₁b₁) + a₂b₂ in IEEE doubles, each product and sum rounded
    (no fused multiply-add): the same bits on every CPU and as `dot_rows`' rows. numpy's `a @ b`
    calls the BLAS ddot, whose kernel, and so whose last bit, depends on the CPU (OpenBLAS's
    Haswell kernel sums as here; its SkylakeX kernel differs in about a quarter of random triples),
    so the per-spacecraft code and its array twins would part on an AVX-512 machine."""
    a0, a1, a2 = np.asarray(a, dtype=float).tolist()
    b0, b1, b2 = np.asarray(b, dtype=float).tolist()
    return a0 * b0 + a1 * b1 + a2 * b2


def dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a_i · b_i of (N, 3) rows, summed left to right: row i the bits of `dot3(a[i], b[i])` on
    every CPU (einsum and matmul order or fuse differently)."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def closest_points_principal(p: np.ndarray, a: np.ndarray, iters: int = 100) -> np.ndarray:
    """`closest_point_principal` of N points (rows of p) on N ellipsoids (rows of a), row i the
    bits of row i's: its Python-float body (`_closest_point`) row by row, without the arrays each
    row's call builds (for the ten or twenty rows of a batch step, faster than the Newton steps
    written out over arrays, whose dozen whole-array operations per iteration cost more than the
    rows' own arithmetic)."""
    pts = np.asarray(p, dtype=float).reshape(-1, 3)
    al = np.asarray(a, dtype=float).reshape(-1, 3)
    out = [_closest_point(pr, ar, iters) for pr, ar in zip(pts.tolist(), al.tolist())]
    return np.array(out, dtype=float).reshape(-1, 3)


def surface_frames(ells: list[Ellipsoid], p_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`surface_frame` of N points (rows of p_m), each on its own ellipsoid: (signed distances (N,),
    closest points (N, 3), outward normals (N, 3)), row i the bits of `surface_frame(ells[i], p_m[i])`:
    the rotations each row's own matrix product, as there (one stacked `np.matmul` of the rows'
    (3, 3) matrices calls for each row the BLAS matrix-vector product that row's `@` calls, with
    the same strides: `_rotate_rows`), the rest over arrays."""
    pts = np.asarray(p_m, dtype=float).reshape(-1, 3)
    if len(ells) != len(pts):
        raise ValueError(f"{len(ells)} ellipsoids for {len(pts)} points")
    rot = _rotations(ells)
    if rot is None:  # a rotation of another layout or type: each row's own product
        local = np.array([e.rotation.T @ (q - e.centre_m) for e, q in zip(ells, pts)]).reshape(-1, 3)
    else:
        centres = np.array([e.centre_m for e in ells], dtype=float).reshape(-1, 3)
        local = _rotate_rows(rot.transpose(0, 2, 1), pts - centres)
    axes = np.array([e.semi_axes_m for e in ells], dtype=float).reshape(-1, 3)
    x = closest_points_principal(local, axes)
    n = x / axes ** 2
    n = n / np.sqrt(dot_rows(n, n))[:, None]
    gap = local - x
    dist = np.sqrt(dot_rows(gap, gap))
    scaled = local / axes
    inside = dot_rows(scaled, scaled) < 1.0
    if rot is None:
        x_s = np.array([e.centre_m + e.rotation @ xi for e, xi in zip(ells, x)]).reshape(-1, 3)
        normals = np.array([e.rotation @ ni for e, ni in zip(ells, n)]).reshape(-1, 3)
    else:
        x_s, normals = centres + _rotate_rows(rot, x), _rotate_rows(rot, n)
    return np.where(inside, -dist, dist), x_s, normals


def _rotations(ells: list[Ellipsoid]) -> np.ndarray | None:
    """The ellipsoids' rotations stacked (N, 3, 3) when every one is a C-ordered float64 (3, 3)
    matrix (then `e.rotation @ v` and `e.rotation.T @ v` have the strides of the stacked rows'
    `rot[i]`, `rot[i].T`); None otherwise (N = 0 included)."""
    mats = [e.rotation for e in ells]
    if not mats or not all(isinstance(m, np.ndarray) and m.dtype == np.float64 and m.shape == (3, 3)
                           and m.flags.c_contiguous for m in mats):
        return None
    return np.array(mats)


def _rotate_rows(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row i: rot[i] @ v[i] ((N, 3, 3) matrices, possibly transposed views, and (N, 3) rows), as one
    stacked matmul: numpy's matmul loop calls the matrix-vector BLAS product for each (3, 3) @ (3, 1)
    as it does for the single `rot[i] @ v[i]` (tests/missions/test_p000_units.py checks the bits)."""
    return np.matmul(rot, np.ascontiguousarray(v)[:, :, None])[:, :, 0]


def signed_distance(ell: Ellipsoid, p_m: np.ndarray) -> float:
    """Euclidean distance to the surface, negative inside."""
    return surface_frame(ell, p_m)[0]


def surface_landmarks(semi_axes_m: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """`count` points spread over the surface (Fibonacci directions scaled), with outward normals,
    in the principal frame: the plant's landmark set (the sensor of `p000-landmarks`) and the
    test loops' synthetic sensor."""
    i = np.arange(count) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / count)
    theta = np.pi * (1.0 + 5.0 ** 0.5) * i
    u = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)
    a = np.asarray(semi_axes_m, dtype=float)
    pts = u * a
    normals = pts / a ** 2
    return pts, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def dcm(q: np.ndarray) -> np.ndarray:
    """Body -> frame rotation matrix of a scalar-first unit quaternion; (4,) -> (3, 3), (N, 4) ->
    (N, 3, 3) with the same elementwise operations per row (so the same bits as row by row)."""
    w, x, y, z = np.moveaxis(np.asarray(q), -1, 0)
    entries = [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
               2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
               2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]
    out = np.empty(np.shape(w) + (9,), dtype=np.result_type(*entries))  # (the stack of the entries)
    for k, e in enumerate(entries):
        out[..., k] = e
    return out.reshape(np.shape(w) + (3, 3))


@dataclass(frozen=True)
class CaptureParams:
    # Table 1 / §4
    mass_kg: float = 10.0
    force_max_n: float = 0.1
    torque_max_nm: float = 0.01
    fov_full_deg: float = 75.0
    k_q: float = 1.8
    k_w: float = 0.25
    k_p: float = 0.5
    k_v: float = 1.2
    k_r: float = 8.0
    k_r_target: float = 0.4
    r_buffer_m: float = 1.0
    r_c_m: float = 9.5
    r_h_m: float = 5.5
    r_l_m: float = 8.5
    f_thr_n: float = 0.1
    # chosen (docs/paper000.md)
    inertia_kgm2: float = 0.075          # diagonal, 8U CubeSat of 10 kg
    search_box_m: float = 15.0           # S of eq. 10: [−15, 15]³
    random_alpha: float = 0.1            # F_rnd = α F_thr, random unit direction
    random_redraw_s: float = 10.0
    buffer_damping_nspm: float = 1.0
    search_attitude: str = "scan"        # "scan" (spin about body z) | "hold" (rate damping only)
    scan_rate_dps: float = 2.0
    chase_law: str = "governed"          # "literal" (eq. 25–26) | "governed" (error clipped)
    approach_speed_mps: float = 0.08     # governed: ‖e‖ clipped at v K_v / K_p
    broadcast: str = "event"             # "event" (eq. 28) | "every-step" | "periodic"
    broadcast_period_s: float = 1.0
    perception_period_s: float = 1.0
    detect_min_returns: int = 8
    fit_min_points: int = 30
    fit_max_points: int = 200
    track_min_inlier_fraction: float = 0.6
    estimate_max_age_s: float = 5.0
    landmarks_per_packet: int = 40
    dock_settle_fits: int = 5
    dock_axes_tol: float = 0.02
    dock_slot_tol_m: float = 0.3
    noise_bound_m: float = 0.1
    mean_motion_radps: float = 0.0011    # 500 km circular LEO (overridden by the OrbitInfo)

    @property
    def inertia(self) -> np.ndarray:
        return np.eye(3) * self.inertia_kgm2

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> "CaptureParams":
        names = {f.name for f in fields(cls)}
        # the scenario loader passes [actuator].max_accel_mps2 to every controller; this agent limits
        # by force (force_max_n), the plant by each [[spacecraft]] max_force_n: ignored here
        unknown = set(params) - names - {"name", "max_accel_mps2"}
        if unknown:
            raise ValueError(f"unknown p000-capture parameters {sorted(unknown)}")
        p = replace(cls(), **{k: v for k, v in params.items() if k in names})
        if p.chase_law not in ("literal", "governed"):
            raise ValueError(f"chase_law must be 'literal' or 'governed', got {p.chase_law!r}")
        if p.broadcast not in ("event", "every-step", "periodic"):
            raise ValueError(f"broadcast must be event|every-step|periodic, got {p.broadcast!r}")
        if p.search_attitude not in ("scan", "hold"):
            raise ValueError(f"search_attitude must be 'scan' or 'hold', got {p.search_attitude!r}")
        return p
