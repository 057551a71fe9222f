"""Paper 004 in the loop, in one process: six p004-lbdnn controllers fly inertial two-body + J2 +
drag dynamics integrated here with scipy's solve_ivp, measurements synthesised from truth.

The plant below is a test-only reference, independent of plant/: the defunct craft's absolute
ECI state plus each servicer's ECI offset from it (integrating offsets keeps metre accuracy at
7000 km radii). Forces: point mass, J2 (Vallado eq. 8-30), drag -1/2 Cd A/m rho |v_rel| v_rel
with an exponential atmosphere (Vallado table 8-4, 300 km row) co-rotating with the Earth.

The paper's case (§6): Table 1 masses and areas, periapsis 300 km / apoapsis 700 km, i = pi/6,
offsets sigma ~ U(2500, 5000) m, azimuth and elevation ~ U(-0.5, 0.5) rad in the defunct craft's
radial / in-track / cross-track frame (seeded), servicers at the defunct craft's velocity;
noise of std sqrt(0.5) m on every component of d_ij and y_i. Choices (docs/paper004.md):
measurements and control at 10 Hz (zero-order hold), the ring graph, b_i = 1 for all.

`PYTHONPATH=. python tests/missions/test_p004_closed_loop.py [NAME...]` prints the figures
quoted in docs/paper004.md (every case, or those whose name contains one of NAME).
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.missions.p004_lbdnn.fsw.sensing import DefunctMeasurement
from swarmhil.claims.check import claim_failures
from swarmhil.claims.paper004 import slug
from swarmhil.missions.p004_lbdnn.contract import SERVICERS, MissionConfig, mission_from_params

MU = 3.986004418e14
R_E = 6378137.0
J2 = 1.08262668e-3
OMEGA_E = 7.292115e-5
CD = 2.2
RHO0, H0, HSCALE = 2.418e-11, 300e3, 53.628e3  # Vallado table 8-4, 300-350 km band

MASS_KG = np.array([10000.0, 640.1074, 1087.4786, 25.1687, 470.9405, 241.4649, 161.1994])
AREA_M2 = np.array([1000.0, 10.1267, 17.9324, 20.4416, 27.4020, 21.5405, 34.5757])
NOISE_STD_M = np.sqrt(0.5)
DIVERGED_M = 1e6  # a servicer 1000 km from the defunct craft: the loop has gone unstable


def accel_natural(r: np.ndarray, v: np.ndarray, area_over_mass: np.ndarray) -> np.ndarray:
    """Two-body + J2 + drag for rows of r, v (n, 3) in ECI."""
    rn = np.linalg.norm(r, axis=1, keepdims=True)
    a = -MU * r / rn**3
    z2 = (r[:, 2:3] / rn) ** 2
    k = -1.5 * J2 * MU * R_E**2 / rn**5
    a = a + k * r * np.hstack([1 - 5 * z2, 1 - 5 * z2, 3 - 5 * z2])
    rho = RHO0 * np.exp(-(rn - R_E - H0) / HSCALE)
    v_rel = v.copy()  # v - omega_E x r, the air co-rotating with the Earth
    v_rel[:, 0] += OMEGA_E * r[:, 1]
    v_rel[:, 1] -= OMEGA_E * r[:, 0]
    return a - 0.5 * CD * area_over_mass[:, None] * rho * np.linalg.norm(v_rel, axis=1, keepdims=True) * v_rel


def rhs(_t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """x = [r0, v0, (dr_i, dv_i) for i = 1..6]; offsets from the defunct craft, u (6, 3) on servicers."""
    s = x.reshape(7, 6)
    r = s[:, :3].copy()
    v = s[:, 3:].copy()
    r[1:] += r[0]
    v[1:] += v[0]
    a = accel_natural(r, v, AREA_M2 / MASS_KG)
    out = np.empty_like(s)
    out[:, :3] = s[:, 3:]
    out[0, 3:] = a[0]
    out[1:, 3:] = a[1:] - a[0] + u
    return out.ravel()


def initial_state(seed: int) -> np.ndarray:
    """The paper's orbit at periapsis and six seeded offsets at the defunct craft's velocity."""
    inc = np.pi / 6
    r_p, r_a = R_E + 300e3, R_E + 700e3
    a = 0.5 * (r_p + r_a)  # the mean of the radii (NOTES-004), not of the altitudes
    v_p = np.sqrt(MU * (2 / r_p - 1 / a))
    r0 = np.array([r_p, 0.0, 0.0])
    v0 = v_p * np.array([0.0, np.cos(inc), np.sin(inc)])
    radial = r0 / np.linalg.norm(r0)
    normal = np.cross(r0, v0)
    normal /= np.linalg.norm(normal)
    along = np.cross(normal, radial)
    rng = np.random.default_rng(seed)
    x = np.zeros((7, 6))
    x[0] = np.concatenate([r0, v0])
    for i in range(1, 7):
        sigma = rng.uniform(2500.0, 5000.0)
        gam, phi = rng.uniform(-0.5, 0.5, size=2)
        q = sigma * np.array([np.cos(phi) * np.cos(gam), np.cos(phi) * np.sin(gam), np.sin(phi)])
        x[i, :3] = q[0] * radial + q[1] * along + q[2] * normal
    return x.ravel()


def nudged(x: np.ndarray, k: int) -> np.ndarray:
    """x with the k-th of the 18 servicer offset coordinates (k = 1..18, cycling) moved up by one
    ulp (about 5e-13 m at 3 km); k = 0: x unchanged."""
    if k <= 0:
        return x
    out = x.reshape(7, 6).copy()
    i, c = divmod((k - 1) % 18, 3)
    out[1 + i, c] = np.nextafter(out[1 + i, c], np.inf)
    return out.ravel()


@dataclass
class Run:
    """Time histories of one closed-loop run (row k: after the controllers' step at t_k)."""

    t: np.ndarray
    e_norm: np.ndarray  # (K, 6) ||e_i||, m
    zeta_tilde_norm: np.ndarray  # (K, 6) ||eta_dot_i - zeta_hat_i||, m/s (Fig. 3's quantity)
    u_norm: np.ndarray  # (K, 6) ||u_i||, m/s^2
    theta_norm: np.ndarray  # (K, 6) ||theta_hat_i||
    phi_norm: np.ndarray  # (K, 6) ||Phi_i(kappa_i, theta_hat_i)||, m/s^2
    lyap: np.ndarray  # (K,) V without the theta_tilde block: 1/2 ||(e, r, eta~, r~, rho)||^2
    lambda_min_h: float
    delta_v_mps: np.ndarray  # (6,) sum ||u|| dt
    wall_s: float
    packet_bytes: int = 0
    diverged_at_s: float | None = None  # first time max ||e_i|| passed DIVERGED_M (run stopped)


def simulate(duration_s: float = 360.0, dt: float = 0.1, seed: int = 4, noise: bool = True,
             params: dict | None = None, noise_fn=None, nudge: int = 0) -> Run:
    """noise_fn(step, index, n_neighbours, m_rows) -> (d noise (n, 3), y noise (m,)): the
    measurement noise (default: one generator seeded seed + 100, drawn in servicer order); the
    stack test passes the plant's sensing kind's draws (missions/p004_lbdnn/sense.py measurement_noise).
    nudge k > 0: the initial state with one servicer offset coordinate moved by one ulp (`nudged`),
    a last-bit change of the kind another CPU's kernels make (docs/claims.md "One-ulp nudges")."""
    params = dict(params or {})
    mission: MissionConfig = mission_from_params({k: v for k, v in params.items() if k != "weight_bytes"})
    g = mission.gains
    h_mat = mission.interaction_matrix()
    orbit = OrbitInfo(semi_major_axis_m=R_E + 500e3, mean_motion_radps=np.sqrt(MU / (R_E + 500e3) ** 3))
    ctrls = [make_controller("p004-lbdnn", s, orbit, params) for s in SERVICERS]
    rng = np.random.default_rng(seed + 100)
    x = nudged(initial_state(seed), nudge)
    n_steps = int(round(duration_s / dt))
    u = np.zeros((6, 3))
    inbox: dict[str, list] = {s: [] for s in SERVICERS}
    rows = []
    dv = np.zeros(6)
    wall0 = time.perf_counter()
    packet_bytes = 0
    diverged_at = None
    for k in range(n_steps + 1):
        t = k * dt
        s = x.reshape(7, 6)
        dq = s[1:, :3]  # q_i - q0
        e = -dq  # e_i = q0 - q_i
        e_dot = -s[1:, 3:]
        outbox: dict[str, list] = {sid: [] for sid in SERVICERS}
        for i, (sid, ctrl) in enumerate(zip(SERVICERS, ctrls)):
            cfg = ctrl.cfg
            nb = list(cfg.neighbours)
            idx = [SERVICERS.index(j) for j in nb]
            c = cfg.c_matrix
            if noise_fn is not None and noise:
                d_noise, y_noise = noise_fn(k, i, len(nb), c.shape[0])
            elif noise:
                d_noise = rng.normal(0, NOISE_STD_M, (len(nb), 3))
                y_noise = rng.normal(0, NOISE_STD_M, c.shape[0])
            else:
                d_noise = y_noise = 0.0
            d = dq[idx] - dq[i] + d_noise
            y = c @ e[i] + y_noise
            extra = DefunctMeasurement(y_m=y).to_extra() if cfg.b else {}
            obs = Observation(step=k, t_s=t, u_rad=0.0, neighbour_ids=nb, rel_position_m=d,
                              rel_velocity_mps=np.zeros_like(d), extra=extra, isl_rx=inbox[sid])
            cmd = ctrl.step(obs)
            u[i] = cmd.accel_mps2
            for tx in cmd.transmissions:
                packet_bytes = len(tx.payload)
                for j in nb:  # the link: broadcast reaches the graph neighbours, next step
                    outbox[j].append(SimpleNamespace(src=sid, type=tx.type, payload=tx.payload, sent_t=t))
        inbox = outbox
        # truth-side figures at t_k
        eta_true = (h_mat @ e.ravel()).reshape(6, 3)
        eta_dot_true = (h_mat @ e_dot.ravel()).reshape(6, 3)
        st = [c.state for c in ctrls]
        zeta_tilde = eta_dot_true - np.array([q.zeta_hat for q in st])
        eta_tilde = eta_true - np.array([q.eta_hat for q in st])
        rho = np.array([q.rho for q in st])
        r = e_dot + g.k1 * e
        r_tilde = zeta_tilde + g.k3 * eta_tilde + rho
        lyap = 0.5 * sum(float(np.sum(v**2)) for v in (e, r, eta_tilde, r_tilde, rho))
        rows.append((t, np.linalg.norm(e, axis=1), np.linalg.norm(zeta_tilde, axis=1),
                     np.linalg.norm(u, axis=1), np.array([np.linalg.norm(q.theta_hat) for q in st]),
                     np.array([np.linalg.norm(q.phi) for q in st]), lyap))
        if k == n_steps:
            break
        if np.max(np.linalg.norm(e, axis=1)) > DIVERGED_M:
            diverged_at = t
            break
        dv += np.linalg.norm(u, axis=1) * dt
        t_next = (k + 1) * dt
        sol = solve_ivp(rhs, (t, t_next), x, method="DOP853", rtol=1e-11, atol=1e-7,
                        first_step=t_next - t, args=(u.copy(),))
        if not sol.success:
            raise RuntimeError(f"integration failed at t = {t}: {sol.message}")
        x = sol.y[:, -1]
    wall = time.perf_counter() - wall0
    return Run(t=np.array([r[0] for r in rows]), e_norm=np.array([r[1] for r in rows]),
               zeta_tilde_norm=np.array([r[2] for r in rows]), u_norm=np.array([r[3] for r in rows]),
               theta_norm=np.array([r[4] for r in rows]), phi_norm=np.array([r[5] for r in rows]),
               lyap=np.array([r[6] for r in rows]),
               lambda_min_h=mission.lambda_min_h(), delta_v_mps=dv, wall_s=wall, packet_bytes=packet_bytes,
               diverged_at_s=diverged_at)


def first_time_below(t: np.ndarray, y: np.ndarray, level: float) -> float:
    """First time after which y stays below level (inf if never)."""
    above = np.nonzero(y >= level)[0]
    if above.size == 0:
        return float(t[0])
    return float(t[above[-1] + 1]) if above[-1] + 1 < t.size else float("inf")


def summary(run: Run) -> dict[str, float]:
    if run.diverged_at_s is not None:
        return {"lambda_min_H": run.lambda_min_h, "diverged_at_s": run.diverged_at_s,
                "e_max_m": float(run.e_norm.max()), "wall_s": run.wall_s}
    after200 = run.t >= 200.0
    after150 = run.t >= 150.0
    return {
        "lambda_min_H": run.lambda_min_h,
        "e_mean_after_200s_m": float(run.e_norm[after200].mean()),
        "e_max_after_200s_m": float(run.e_norm[after200].max()),
        "t_e_below_10m_s": max(first_time_below(run.t, run.e_norm[:, i], 10.0) for i in range(6)),
        "zeta_tilde_mean_after_150s_mps": float(run.zeta_tilde_norm[after150].mean()),
        "zeta_tilde_max_after_150s_mps": float(run.zeta_tilde_norm[after150].max()),
        "u_peak_mps2": float(run.u_norm.max()),
        "u_mean_mps2": float(run.u_norm.mean()),
        "u_mean_after_200s_mps2": float(run.u_norm[after200].mean()),
        "delta_v_max_mps": float(run.delta_v_mps.max()),
        "theta_norm_max": float(run.theta_norm.max()),
        "phi_mean_after_200s_mps2": float(run.phi_norm[after200].mean()),
        "V0": float(run.lyap[0]),
        "V_end": float(run.lyap[-1]),
        "V_decay_rate_0_40s_per_s": float(np.log(run.lyap[0] / run.lyap[run.t <= 40.0][-1]) / 40.0),
        "packet_bytes": float(run.packet_bytes),
        "wall_s": run.wall_s,
    }


# ---------------------------------------------------------------------------------------------

def test_reference_plant_keeps_the_paper_orbit() -> None:
    """The test's own plant: with no control the offsets stay near their start for 30 s (same
    velocity), and the 0.1 s single DOP853 steps of the loop agree with one tight integration."""
    x0 = initial_state(4)
    u0 = np.zeros((6, 3))
    sol = solve_ivp(rhs, (0.0, 30.0), x0, method="DOP853", rtol=1e-13, atol=1e-9, args=(u0,))
    s0, s1 = x0.reshape(7, 6), sol.y[:, -1].reshape(7, 6)
    x = x0
    for k in range(300):
        t, t_next = k * 0.1, (k + 1) * 0.1
        x = solve_ivp(rhs, (t, t_next), x, method="DOP853", rtol=1e-11, atol=1e-7,
                      first_step=t_next - t, args=(u0,)).y[:, -1]
    chained = x.reshape(7, 6)
    assert np.max(np.abs(chained[1:, :3] - s1[1:, :3])) < 1e-3  # offsets to the millimetre
    assert np.max(np.abs(chained[0, :3] - s1[0, :3])) < 1e-2
    assert np.linalg.norm(s0[0, :3]) == pytest.approx(R_E + 300e3)
    drift = np.linalg.norm(s1[1:, :3] - s0[1:, :3], axis=1)
    assert np.all(drift < 20.0)  # gravity gradient: n^2 sigma t^2 < 1.3e-6 * 5000 * 900 = 6 m
    assert np.all(np.linalg.norm(s0[1:, :3], axis=1) >= 2500.0)


@pytest.fixture(scope="module")
def paper_run() -> Run:
    """The paper's case for 250 s (the claims are about 150 s and 200 s; the full 360 s run is
    the system test below, kept out of the default set for time: ~45 s on a loaded machine)."""
    return simulate(duration_s=250.0, dt=0.1, seed=4)


def assert_paper_outcome(run: Run) -> None:
    """§6: tracking errors converge to a few metres by 200 s, neighbourhood-velocity errors of a
    few m/s by 150 s, all bounded; weights inside the projection's ball."""
    s = summary(run)
    print({k: round(v, 4) for k, v in s.items()})
    assert run.e_norm[0].min() > 2000.0
    # bounds from the measured spread with a stated margin: the 360 s run of docs/paper004.md under
    # two kernel sets and eight one-ulp nudges of its initial state (claims/recorded.json
    # p004.paper.*: value, alt, nudged; AVX2 machine): max error after 200 s 2.79-5.57 m, bound 8 m
    # (1.4x); mean 0.93-1.69 m, bound 2.5 m (1.5x); all below 10 m from 42.8 s in every run, bound
    # 60 s (1.4x); zeta-tilde max after 150 s 9.77-9.78 m/s, bound 15 m/s (1.5x). The 250 s fixture
    # run is the same trajectory up to 250 s, so its window lies inside these.
    assert s["e_max_after_200s_m"] < 8.0
    assert s["e_mean_after_200s_m"] < 2.5
    assert s["t_e_below_10m_s"] < 60.0
    assert s["zeta_tilde_max_after_150s_mps"] < 15.0
    assert np.all(np.isfinite(run.u_norm)) and s["u_peak_mps2"] < 1e4
    assert s["theta_norm_max"] <= 31.0 + 1e-9  # theta_bar + epsilon of the projection


def test_paper_case_converges_and_stays_bounded(paper_run: Run) -> None:
    assert_paper_outcome(paper_run)


@pytest.mark.system
def test_paper_case_full_360s() -> None:
    run = simulate(duration_s=360.0, dt=0.1, seed=4)
    assert_paper_outcome(run)
    assert run.lyap[-1] < 1e-5 * run.lyap[0]
    assert claim_failures("p004.paper", run) == []  # docs/paper004.md's row, from this run (claims/check.py)


def test_lyapunov_function_decays_to_a_neighbourhood(paper_run: Run) -> None:
    """Theorem 1's shape (eq. 58), V(t) <= V(0) exp(-c t) + b: V falls by orders of magnitude
    at a rate c, then stays in a noise-sized neighbourhood b (measured here: b from t >= 100 s)."""
    v, t = paper_run.lyap, paper_run.t
    floor = v[t >= 100.0].max()
    assert v[-1] < 1e-4 * v[0] and floor < 1e-5 * v[0]
    c = 0.25  # per second; measured 0.36 over the first 40 s (docs/paper004.md)
    assert np.all(v <= v[0] * np.exp(-c * t) + 2.0 * floor)
    # the transient itself: each 10 s window's maximum below the previous one until 40 s
    windows = [v[(t >= a) & (t < a + 10.0)].max() for a in (0.0, 10.0, 20.0, 30.0)]
    assert all(b < a for a, b in zip(windows, windows[1:]))


CI_VARIANTS = {"no network (Phi = 0)", "thrust limit 10 m/s^2 per axis"}  # the rest: `make test-study`
VARIANTS: dict[str, tuple[dict, str]] = {
    # name: (keyword arguments of simulate(), expected outcome: converges | bounded | diverges)
    "no network (Phi = 0)": ({"params": {"use_network": False}}, "converges"),
    "path graph": ({"params": {"graph": "path"}}, "converges"),
    "b_i = 1 for s4 only": ({"params": {"b": {s: int(s == "s4") for s in SERVICERS}}}, "bounded"),
    "b_i = 1 for s4 only, no network": ({"params": {"b": {s: int(s == "s4") for s in SERVICERS},
                                                    "use_network": False}}, "bounded"),
    "5 Hz": ({"dt": 0.2}, "diverges"),  # dt > 2 / (k2 lambda_max(H)) = 0.18 s
    "20 Hz": ({"dt": 0.05}, "converges"),
    "noise-free measurements": ({"noise": False}, "converges"),
    "thrust limit 10 m/s^2 per axis": ({"params": {"max_accel_mps2": 10.0}}, "converges"),
    "thrust limit 1 m/s^2 per axis": ({"params": {"max_accel_mps2": 1.0}}, "bounded"),
}


# Max error after 200 s of each converging variant (360 s, seed 4; AVX2 machine): the largest of its
# runs under two kernel sets (default / OPENBLAS_CORETYPE=Sandybridge NPY_DISABLE_CPU_FEATURES=X86_V3)
# and eight one-ulp nudges of the initial state (claims/recorded.json p004.*.e-max: value, alt,
# nudged), with a margin of about a third. A one-sided guard: the claims check below is the tight
# one (broken on purpose, k1 = 0.4 without the network gives e max 0.894 m, inside this bound, and
# fails its claims: 2026-12-03).
E_MAX_AFTER_200S_BOUND_M = {
    "no network (Phi = 0)": 1.17,  # 0.974 m in all ten runs
    "path graph": 4.75,  # 3.941-3.955 m
    "20 Hz": 4.2,  # 1.470-2.474 m (the network amplifies the last bits)
    "noise-free measurements": 2.67,  # 2.226 m in all ten runs
    "thrust limit 10 m/s^2 per axis": 12.6,  # 6.682-9.438 m
}


@pytest.mark.system
@pytest.mark.parametrize("name", [pytest.param(n, marks=() if n in CI_VARIANTS else pytest.mark.study) for n in VARIANTS])
def test_variants(name: str) -> None:
    """The ablation and the variants of docs/paper004.md, each with the outcome measured there."""
    kwargs, expected = VARIANTS[name]
    run = simulate(**kwargs)
    s = summary(run)
    print(name, {k: round(v, 4) for k, v in s.items()})
    if expected == "diverges":
        assert run.diverged_at_s is not None
        return
    assert run.diverged_at_s is None
    assert np.all(np.isfinite(run.e_norm)) and np.all(np.isfinite(run.u_norm))
    assert run.e_norm[-1].max() < run.e_norm[0].max()
    if expected == "converges":
        assert s["e_max_after_200s_m"] < E_MAX_AFTER_200S_BOUND_M[name]
    assert claim_failures(f"p004.{slug(name)}", run) == []  # its docs/paper004.md row (claims/check.py)


if __name__ == "__main__":
    cases = {"paper (ring, b_i = 1, network, 10 Hz)": {}, **{k: v[0] for k, v in VARIANTS.items()}}
    wanted = sys.argv[1:]
    for name, kwargs in cases.items():
        if wanted and not any(w in name for w in wanted):
            continue
        run = simulate(**kwargs)
        print(name, {k: round(v, 4) for k, v in summary(run).items()}, flush=True)
