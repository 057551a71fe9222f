"""The Tersoff-Brenner bond-order energy (paper 001 eq. 6-12, Table 2) and its exact gradient.

Normalised units: distances in units of the desired side l (R_e = 1), energy in units of the
well depth (D_e = 1). Everything here is a pure function of an (n, 3) array of positions.

E = 1/2 sum_{i!=j} [V_R(r_ij) - B_ij V_A(r_ij)]               (eq. 6 with eq. 10 expanded)
V_R = f(r) D_e/(S-1) exp(-sqrt(2S) beta (r-R_e))              (eq. 7)
V_A = f(r) D_e S/(S-1) exp(-sqrt(2/S) beta (r-R_e))           (eq. 8)
f   = 1, 1/2[1+cos(pi (r-R1)/(R2-R1))], 0                       (eq. 9)
B_ij = [1 + sum_{k!=i,j} G(cos theta_ijk) f(r_ik)]^-delta      (eq. 11)
G(c) = a0 [1 + c0^2/d0^2 - c0^2/(d0^2 + (1+c)^2)]             (eq. 12)
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from swarmhil.missions.p001_lattice.contract import BRENNER_RE_ANGSTROM, CUTOFF_READINGS


@dataclass(frozen=True)
class TersoffParams:
    """Table 2, TB module (normalised). R1, R2 as printed are Brenner's angstrom values."""

    d_e: float = 1.0
    r_e: float = 1.0
    beta: float = 1.9725
    s: float = 1.29
    delta: float = 0.80469
    a0: float = 1.1304e-2
    c0: float = 19.0
    d0: float = 2.5
    r1: float = 1.95
    r2: float = 2.25


def tersoff_params(cutoff_reading: str = "normalised") -> TersoffParams:
    """Table 2 with the truncation distances read literally or divided by R_e = 1.315 (NOTES-001)."""
    p = TersoffParams()
    if cutoff_reading == "literal":
        return p
    if cutoff_reading == "normalised":
        return replace(p, r1=p.r1 / BRENNER_RE_ANGSTROM, r2=p.r2 / BRENNER_RE_ANGSTROM)
    raise ValueError(f"cutoff_reading {cutoff_reading!r} not in {CUTOFF_READINGS}")


def cutoff(r: np.ndarray, p: TersoffParams) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 9: f(r) and df/dr."""
    r = np.asarray(r, dtype=float)
    x = np.clip((r - p.r1) / (p.r2 - p.r1), 0.0, 1.0)
    f = 0.5 * (1.0 + np.cos(np.pi * x))
    inside = (r > p.r1) & (r < p.r2)
    df = np.where(inside, -0.5 * np.pi / (p.r2 - p.r1) * np.sin(np.pi * x), 0.0)
    return f, df


def pair_terms(r: np.ndarray, p: TersoffParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 7-8 with the cutoff: V_R, dV_R/dr, V_A, dV_A/dr."""
    f, df = cutoff(r, p)
    kr = np.sqrt(2.0 * p.s) * p.beta
    ka = np.sqrt(2.0 / p.s) * p.beta
    er = p.d_e / (p.s - 1.0) * np.exp(-kr * (r - p.r_e))
    ea = p.d_e * p.s / (p.s - 1.0) * np.exp(-ka * (r - p.r_e))
    return f * er, df * er - f * kr * er, f * ea, df * ea - f * ka * ea


def angle_term(c: np.ndarray, p: TersoffParams) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 12: G(cos theta) and dG/dcos theta."""
    q = p.d0**2 + (1.0 + c) ** 2
    g = p.a0 * (1.0 + p.c0**2 / p.d0**2 - p.c0**2 / q)
    dg = p.a0 * p.c0**2 * 2.0 * (1.0 + c) / q**2
    return g, dg


def _geometry(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pair vectors r_ij = x_j - x_i, distances, unit vectors, and the off-diagonal mask."""
    n = pos.shape[0]
    rv = pos[None, :, :] - pos[:, None, :]
    off = ~np.eye(n, dtype=bool)
    d = np.linalg.norm(rv, axis=2)
    if np.any(d[off] <= 0.0):
        raise ValueError("two agents at the same position: the TB energy is undefined")
    dsafe = np.where(off, d, 1.0)
    return rv, dsafe, rv / dsafe[:, :, None], off


def _bond_order(u: np.ndarray, d: np.ndarray, off: np.ndarray, p: TersoffParams):
    """Eq. 11: b_ij = 1 + sum_k G(c_ijk) f(r_ik), with the pieces the gradient needs."""
    n = d.shape[0]
    c = np.einsum("ijx,ikx->ijk", u, u)
    g, dg = angle_term(c, p)
    f, df = cutoff(d, p)
    f = np.where(off, f, 0.0)
    df = np.where(off, df, 0.0)
    trip = off[:, :, None] & off[:, None, :] & ~np.eye(n, dtype=bool)[None, :, :]  # i!=j, i!=k, j!=k
    b = 1.0 + np.einsum("ijk,ik->ij", np.where(trip, g, 0.0), f)
    return b, c, g, dg, f, df, trip


def energy(pos: np.ndarray, p: TersoffParams) -> float:
    """Eq. 6: the total TB binding energy of the configuration (n, 3)."""
    pos = np.asarray(pos, dtype=float)
    if pos.shape[0] < 2:
        return 0.0
    _rv, d, u, off = _geometry(pos)
    vr, _dvr, va, _dva = pair_terms(d, p)
    b, *_ = _bond_order(u, d, off, p)
    bij = b ** (-p.delta)
    return float(0.5 * np.sum(np.where(off, vr - bij * va, 0.0)))


def gradient(pos: np.ndarray, p: TersoffParams) -> np.ndarray:
    """dE/dx for every agent (n, 3): pair, cutoff, bond-order and angle terms, exactly (eq. 13)."""
    pos = np.asarray(pos, dtype=float)
    n = pos.shape[0]
    grad = np.zeros((n, 3))
    if n < 2:
        return grad
    _rv, d, u, off = _geometry(pos)
    vr, dvr, va, dva = pair_terms(d, p)
    b, c, g, dg, f, df, trip = _bond_order(u, d, off, p)
    bij = b ** (-p.delta)

    # direct pair terms: dE/dr_ij = 1/2 (V_R' - B_ij V_A'), r_ij depends on x_j (+u) and x_i (-u)
    s = np.where(off, 0.5 * (dvr - bij * dva), 0.0)
    fij = s[:, :, None] * u
    grad += np.sum(fij, axis=0) - np.sum(fij, axis=1)

    # bond order: dE/db_ij = 1/2 delta V_A b^(-delta-1)
    w = np.where(off, 0.5 * p.delta * va * b ** (-p.delta - 1.0), 0.0)
    a = np.where(trip, w[:, :, None] * dg * f[:, None, :], 0.0)  # times d c_ijk
    cc = np.where(trip, w[:, :, None] * g * df[:, None, :], 0.0)  # times d r_ik
    # d c / d r_ij = (u_ik - c u_ij)/r_ij ; d c / d r_ik = (u_ij - c u_ik)/r_ik
    dc_drij = (u[:, None, :, :] - c[:, :, :, None] * u[:, :, None, :]) / d[:, :, None, None]
    dc_drik = (u[:, :, None, :] - c[:, :, :, None] * u[:, None, :, :]) / d[:, None, :, None]
    to_j = np.einsum("ijk,ijkx->ijx", a, dc_drij)  # acts on x_j
    to_k = np.einsum("ijk,ijkx->ikx", a, dc_drik) + np.einsum("ijk,ikx->ikx", cc, u)  # acts on x_k
    grad += np.sum(to_j, axis=0) + np.sum(to_k, axis=0)
    grad -= np.sum(to_j, axis=1) + np.sum(to_k, axis=1)
    return grad


def forces(pos: np.ndarray, p: TersoffParams) -> np.ndarray:
    """Eq. 13: F_i = -dE/dx_i (normalised)."""
    return -gradient(pos, p)
