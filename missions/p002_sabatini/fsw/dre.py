"""Periodic time-varying LQR gains from the differential Riccati equation (paper 002 section 3.4).

The plant of the behavioural laws is Eq. (2), d(dalpha)/dt = A dalpha + B(u) u_c, with the
dimensionless ROE dalpha and u_c in m/s^2 (agent/roe.py). B depends on the reference argument of
latitude u = n t, so the LQR gain comes from the differential Riccati equation (DRE)

    -dP/dt = A' P + P A - P B(u) R^-1 B(u)' P + Q,        K(u) = R^-1 B(u)' P(u),

whose stabilising solution is periodic in u with period 2 pi. It is found by integrating the DRE
backward in time, one orbit at a time from P = 0, until P at the start of the orbit repeats; the
last orbit is tabulated on a uniform grid of u. Weights (NOTES-002): Q as printed in the paper for
the dimensionless ROE, R in SI (m/s^2)^-2, i.e. the paper's 1e4, 1e6, 1e5 in (km/s^2)^-2 become
1e-2, 1 and 1e-1.

The table is computed once per (orbit, weights, grid) and cached for the life of the process, and
on disk (issue 16): `$SWARMHIL_CACHE_DIR` (default `$XDG_CACHE_HOME/swarmhil` or `~/.cache/swarmhil`),
one .npz per table, keyed by the inputs, this module's and agent/roe.py's source, the numpy
and scipy versions and the kernel set (`kernel_set`: the processor and the environment's
overrides of its kernels), so a cached table is the table this code would compute here, bit for bit. A process
that finds its tables there never imports scipy.integrate (about 60 MB of an agent process's
memory and 1-2 s of its start). `SWARMHIL_CACHE_DIR=off` disables the disk cache.
"""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from swarmhil.agent import roe
from swarmhil.agent.roe import input_matrix, state_matrix

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class GainTable:
    """Periodic LQR gain tabulated by u: accel_mps2 = -gain(u) @ error_roe_m."""

    u_grid_rad: np.ndarray  # (N,) uniform over [0, 2 pi)
    gain_per_s2: np.ndarray  # (N, 3, 6) gain on the ROE error in metres: (m/s^2) per m
    riccati: np.ndarray  # (N, 6, 6) P(u) of the dimensionless problem
    orbits_to_converge: int
    # the last lookup (u, gain): the table is shared by every controller of a process (gain_table's
    # cache) and all spacecraft ask for the same u in a step, so in batch mode it is computed once
    # per step instead of once per spacecraft (issue 16); the same arithmetic, a read-only result
    _last: list = field(default_factory=lambda: [(None, None)], init=False, repr=False, compare=False)

    def gain(self, u_rad: float) -> np.ndarray:
        """(3, 6) gain at u, linear interpolation between the periodic table's nodes (read-only)."""
        u = float(u_rad)
        u_last, g_last = self._last[0]
        if u_last == u:
            return g_last
        g = interpolate_periodic(self.gain_per_s2, u)
        g.setflags(write=False)
        self._last[0] = (u, g)  # one assignment: a reader never sees a half-updated pair
        return g


def interpolate_periodic(table: np.ndarray, u_rad: float, axis: int = 0) -> np.ndarray:
    """Linear interpolation in u of a table over a uniform periodic grid of [0, 2 pi) along `axis`
    (the gains of several tables stacked on axis 0 when axis = 1: the same values as one by one)."""
    u = float(u_rad)
    n_table = table.shape[axis]
    x = (u % TWO_PI) / TWO_PI * n_table
    fl = math.floor(x)  # (np.floor's value: x is a finite float >= 0; a NaN raises as int(np.floor(x)) does)
    i0 = fl % n_table
    f = x - fl
    t0 = table.take(i0, axis=axis)
    t1 = table.take((i0 + 1) % n_table, axis=axis)
    return (1.0 - f) * t0 + f * t1


_STACKED: dict[tuple[int, ...], tuple[tuple[GainTable, ...], np.ndarray]] = {}


def stacked_gains(tables: tuple[GainTable, ...]) -> np.ndarray:
    """(len(tables), n_table, 3, 6) read-only: several gain tables of one grid side by side, to
    interpolate all of them in one pass (`interpolate_periodic(..., axis=1)`); kept per set of
    tables (the tables themselves are shared, `gain_table`'s cache)."""
    key = tuple(id(t) for t in tables)
    hit = _STACKED.get(key)
    if hit is None:
        out = np.stack([t.gain_per_s2 for t in tables])
        out.setflags(write=False)
        hit = _STACKED[key] = (tables, out)  # the tables kept alive: their ids stay theirs
    return hit[1]


def riccati_rate(t_s: float, p_flat: np.ndarray, a_mat: np.ndarray, q_mat: np.ndarray, r_inv: np.ndarray,
                 a_m: float, n_radps: float) -> np.ndarray:
    """dP/dt of the DRE (section 3.4), P flattened row-major; u = n t."""
    p = p_flat.reshape(6, 6)
    b = input_matrix(n_radps * t_s, a_m, n_radps)
    pb = p @ b
    dp = -(a_mat.T @ p + p @ a_mat - pb @ r_inv @ pb.T + q_mat)
    return dp.ravel()


def integrate_riccati_one_orbit(p_end: np.ndarray, a_m: float, n_radps: float, q_diag: np.ndarray,
                                r_diag: np.ndarray, rtol: float = 1e-10):
    """Integrate the DRE backward over one orbit, t = T -> 0 (u = 2 pi -> 0); returns the solve_ivp result."""
    period_s = TWO_PI / n_radps
    args = (state_matrix(n_radps), np.diag(q_diag), np.diag(1.0 / r_diag), a_m, n_radps)
    from scipy.integrate import solve_ivp  # here, not at import: agents with cached tables never load it

    scale = max(1.0, float(np.max(np.abs(p_end))))
    return solve_ivp(riccati_rate, (period_s, 0.0), p_end.ravel(), method="DOP853", args=args,
                     rtol=rtol, atol=rtol * scale, dense_output=True)


def periodic_riccati(a_m: float, n_radps: float, q_diag: np.ndarray, r_diag: np.ndarray, n_table: int = 720,
                     tol: float = 1e-9, max_orbits: int = 200) -> tuple[np.ndarray, np.ndarray, int]:
    """Periodic solution P(u) of the DRE on u = 2 pi i / n_table; returns (u_grid, P (N,6,6), orbits used).

    Converged when one more backward orbit changes P(0) by less than tol relative to max |P|.
    """
    q_diag = np.asarray(q_diag, dtype=float)
    r_diag = np.asarray(r_diag, dtype=float)
    p_end = np.zeros((6, 6))
    for orbit in range(1, max_orbits + 1):
        sol = integrate_riccati_one_orbit(p_end, a_m, n_radps, q_diag, r_diag)
        if not sol.success:
            raise RuntimeError(f"DRE integration failed: {sol.message}")
        p_start = sol.y[:, -1].reshape(6, 6)
        change = np.max(np.abs(p_start - p_end)) / max(np.max(np.abs(p_start)), 1e-300)
        p_end = 0.5 * (p_start + p_start.T)
        if orbit > 1 and change < tol:
            break
    else:
        raise RuntimeError(f"DRE did not reach its periodic solution in {max_orbits} orbits (change {change:.2e})")
    u_grid = TWO_PI * np.arange(n_table) / n_table
    p_table = sol.sol(u_grid / n_radps).T.reshape(n_table, 6, 6)
    p_table = 0.5 * (p_table + p_table.transpose(0, 2, 1))
    return u_grid, p_table, orbit


def _compute_table(a_m: float, n_radps: float, q_diag: tuple[float, ...], r_diag: tuple[float, ...],
                   n_table: int) -> GainTable:
    u_grid, p_table, orbits = periodic_riccati(a_m, n_radps, np.array(q_diag), np.array(r_diag), n_table)
    r_inv = np.diag(1.0 / np.array(r_diag))
    gains = np.empty((n_table, 3, 6))
    for i, u in enumerate(u_grid):
        gains[i] = r_inv @ input_matrix(u, a_m, n_radps).T @ p_table[i] / a_m  # per metre of ROE error
    return GainTable(u_grid, gains, p_table, orbits)


def cache_dir() -> Path | None:
    """Directory of the on-disk gain tables, None when disabled (SWARMHIL_CACHE_DIR=off)."""
    d = os.environ.get("SWARMHIL_CACHE_DIR")
    if d is not None:
        return None if d.strip().lower() in ("", "off", "0", "none") else Path(d)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "swarmhil"


@lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    """What the table depends on besides its inputs: this code, the numerical libraries and the
    floating-point kernels they run here (`kernel_set`): the table's last bits differ between
    kernel sets, and a run's truth carries them (docs/determinism.md)."""
    import importlib.metadata as md

    h = hashlib.sha256()
    for path in (Path(__file__), Path(roe.__file__)):
        h.update(path.resolve().read_bytes())
    for dist in ("numpy", "scipy"):
        try:
            h.update(f"{dist}={md.version(dist)}".encode())
        except md.PackageNotFoundError:
            h.update(dist.encode())
    h.update(kernel_set().encode())
    return h.hexdigest()[:16]


def kernel_set() -> str:
    """The floating-point kernels of this process: the processor (model and feature flags, from
    which numpy picks its SIMD loops and the OpenBLAS that numpy and scipy bundle its kernels) and
    the environment that overrides either choice. Two processes with the same string compute the
    same table bits with the same code and libraries."""
    try:
        info = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        info = []
    cpu = [next((ln.split(":", 1)[1].strip() for ln in info if ln.startswith(k)), "") for k in ("model name", "flags")]
    env = [f"{k}={os.environ.get(k, '')}" for k in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES",
                                                    "NPY_ENABLE_CPU_FEATURES")]
    return ";".join([*cpu, *env])


def _cache_file(a_m: float, n_radps: float, q_diag: tuple[float, ...], r_diag: tuple[float, ...],
                n_table: int) -> Path | None:
    d = cache_dir()
    if d is None:
        return None
    key = repr((float(a_m).hex(), float(n_radps).hex(), [float(x).hex() for x in q_diag], [float(x).hex() for x in r_diag], n_table))
    name = hashlib.sha256((key + _code_fingerprint()).encode()).hexdigest()[:32]
    return d / f"dre-{name}.npz"


@lru_cache(maxsize=32)
def _cached_table(a_m: float, n_radps: float, q_diag: tuple[float, ...], r_diag: tuple[float, ...],
                  n_table: int) -> GainTable:
    path = _cache_file(a_m, n_radps, q_diag, r_diag, n_table)
    table = None
    if path is not None and path.is_file():
        try:
            with np.load(path) as z:
                table = GainTable(z["u_grid"], z["gains"], z["riccati"], int(z["orbits"]))
        except (OSError, ValueError, KeyError):
            table = None  # unreadable: computed again (and rewritten) below
    if table is None:
        table = _compute_table(a_m, n_radps, q_diag, r_diag, n_table)
        if path is not None:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
                with open(tmp, "wb") as f:
                    np.savez(f, u_grid=table.u_grid_rad, gains=table.gain_per_s2, riccati=table.riccati,
                             orbits=table.orbits_to_converge)
                os.replace(tmp, path)  # atomic: concurrent processes read a whole file or none
            except OSError:
                pass  # a read-only home is no reason to fail: the table is in memory
    for a in (table.u_grid_rad, table.gain_per_s2, table.riccati):
        a.setflags(write=False)
    return table


def gain_table(a_m: float, n_radps: float, q_diag, r_diag, n_table: int = 720) -> GainTable:
    """Cached periodic gain table for Q = diag(q_diag) (dimensionless ROE) and R = diag(r_diag) (SI).

    A scalar r_diag means r * I3.
    """
    r = np.broadcast_to(np.asarray(r_diag, dtype=float), (3,))
    q = np.asarray(q_diag, dtype=float).reshape(6)
    return _cached_table(float(a_m), float(n_radps), tuple(float(x) for x in q), tuple(float(x) for x in r),
                         int(n_table))
