"""Paper 001's contract: what the flight software, the report and the claims share.

Imports nothing of the project but `bus` (here: nothing at all); numpy only. Read by
missions/p001_lattice/fsw/ (the flight software), missions/p001_lattice/report.py (the report
section) and claims/paper001*.py. docs/architecture.md "Mission rooms (issue 25)". Paper 001 has no
sensing kind of its own: the plant's built-in `relative` kind (plant/sensing/builtin.py) gives the
own state the flight software reads (fsw/sensing.py).

**Name.** `CONTROLLER` is the name the flight software registers and the report looks for.

**Units** (Table 1): the normalisation factors and the SI <-> normalised conversions. Two unit
systems live in this room and nowhere else:
- flight dynamics, normalised by the Earth: length l_e, time t_e = 1/omega_e, so the GEO rate is 1;
- the Tersoff-Brenner (TB) module, where distances are divided by the desired side l (R_e = 1)
  and energies by the well depth D_e = 1.

**Parameter model** (Tables 2-4 in SI, with the readings of the open items as named options):
built from the scenario's `[controller]` table by `LatticeParams.from_dict`; every field has the
paper's value (or this room's stated choice where the paper is silent) as its default.

**Formation measures** (eq. 16 and a geometric hexagon test, NOTES-001 trap 2): pure functions of
an (N, 3) array of positions in metres (CW frame).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

CONTROLLER = "p001-lattice"

# Table 1, space-flight dynamics module
EARTH_RADIUS_M = 6.37813e6  # l_e
EARTH_RATE_RADPS = 7.2921e-5  # omega_e; GEO mean motion
T_E_S = 1.0 / EARTH_RATE_RADPS  # t_e
V_E_MPS = EARTH_RADIUS_M / T_E_S  # v_e ~ 465.1 m/s
A_E_MPS2 = V_E_MPS / T_E_S  # a_e ~ 0.0339 m/s^2

# Table 1, TB module (only their ratio enters eq. 14)
CARBON_MASS_KG = 1.9926e-26  # m_s = m_carbon
CARBON_BOND_M = 1.315e-10  # l_s: Brenner's R_e in metres
TB_WELL_J = 1.0134e-18  # e_s

# Table 4: eq. 14 amplification constant epsilon
TB_EPSILON = 1.9926e-29
TB_GAIN = TB_EPSILON / CARBON_MASS_KG  # epsilon / m_carbon = 1e-3 (the unit is a reading, see params)

BRENNER_RE_ANGSTROM = 1.315  # R_e of Brenner's carbon set II, in angstrom


def rate_from_normalised(value: float) -> float:
    """A coefficient in units of 1/t_e (gain, damping) -> 1/s."""
    return value * EARTH_RATE_RADPS


def stiffness_from_normalised(value: float) -> float:
    """A coefficient in units of 1/t_e^2 (well amplitude alpha) -> 1/s^2."""
    return value * EARTH_RATE_RADPS**2


def area_from_normalised(value: float) -> float:
    """A squared length in units of l_e^2 (well range k) -> m^2."""
    return value * EARTH_RADIUS_M**2

CUTOFF_READINGS = ("normalised", "literal")
"""The readings of the Table 2 truncation distances R(1), R(2) (fsw/tersoff.py tersoff_params)."""

TB_UNITS = ("mps2", "a_e")

ALPHA_F_PS2 = stiffness_from_normalised(5.1676e3)  # Table 4, ~2.75e-5 1/s^2
K_F_M2 = area_from_normalised(3.9822e-10)  # Table 4, ~(127.3 m)^2
GAMMA_PS = rate_from_normalised(2.4027e2)  # Table 4, ~1.75e-2 1/s


@dataclass(frozen=True)
class LatticeParams:
    # Table 2
    mean_motion_radps: float = EARTH_RATE_RADPS
    side_m: float = 10.0  # l
    sensing_radius_m: float = 21.0  # r_Z (applied by the plant; kept here to state it)
    max_accel_mps2: float = 5e-3  # u_max
    t_desire_s: float = 1.95e4
    t_natural_s: float = 0.975 * 1.95e4
    r_outer_m: float = 1000.0
    r_middle_m: float = 100.0
    r_inner_m: float = 15.0
    x_shift_m: float = 0.0
    phase_deg: float = 30.0  # Fig. 1: vertex angles from +y in the yz-plane, 30 + 60 k
    # Table 4
    alpha_free_ps2: float = ALPHA_F_PS2
    k_free_m2: float = K_F_M2
    alpha_planar_ps2: float = ALPHA_F_PS2
    k_planar_m2: float = K_F_M2
    damping_ps: float = GAMMA_PS
    # open items (NOTES-001), named readings
    alpha_phase_ps2: float = ALPHA_F_PS2  # not in Table 4: alpha_ph = alpha_f
    k_phase_m2: float = K_F_M2  # not in Table 4: k_ph = k_f (a ~127 m wide dock well)
    free_in_shaping: bool = False  # Table 3: g_free off in the shaping ball
    cutoff_reading: str = "normalised"  # R(1), R(2) divided by 1.315 (or "literal")
    tb_unit: str = "mps2"  # eq. 14 output read in m/s^2 (or "a_e")
    far_gain_ps: float = 0.05  # k_g, not given
    far_damping: bool = False  # Table 3: no dissipation in the natural gathering layer

    def __post_init__(self) -> None:
        if self.cutoff_reading not in CUTOFF_READINGS:
            raise ValueError(f"cutoff_reading {self.cutoff_reading!r} not in {CUTOFF_READINGS}")
        if self.tb_unit not in TB_UNITS:
            raise ValueError(f"tb_unit {self.tb_unit!r} not in {TB_UNITS}")
        if not self.r_outer_m > self.r_middle_m > self.r_inner_m > 0.0:
            raise ValueError(f"need r_outer > r_middle > r_inner > 0, got {self.r_outer_m}, {self.r_middle_m}, {self.r_inner_m}")
        if not 0.0 < self.t_natural_s < self.t_desire_s:
            raise ValueError(f"need 0 < t_natural < t_desire, got {self.t_natural_s}, {self.t_desire_s}")

    @property
    def tb_accel_unit_mps2(self) -> float:
        """What one unit of eq. 14's output is in m/s^2 under the chosen reading."""
        return 1.0 if self.tb_unit == "mps2" else A_E_MPS2

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> "LatticeParams":
        known = {f.name: f for f in fields(cls)}
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise ValueError(f"unknown p001-lattice parameters {unknown}; known: {sorted(known)}")
        defaults = cls()
        values = {}
        for k, v in params.items():
            kind = type(getattr(defaults, k))
            if kind is bool and not isinstance(v, bool):
                raise ValueError(f"p001-lattice parameter {k} must be true or false, got {v!r}")
            values[k] = kind(v)
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


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
