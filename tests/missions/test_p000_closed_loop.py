"""Paper 000 closed loop in one process: 10 controllers, CW translation + rigid-body attitude,
the drifting tumbling ellipsoid, measurements synthesised from truth (a stand-in for the plant and
sensing kinds the lead will wire; nothing here is imported by the flight software).

Sensing model (chosen, docs/paper000.md): 400 landmarks on the surface; a landmark returns when it
faces the sensor, lies within R_l and inside the 75° full cone about body +x; Gaussian noise
σ = 2 cm per axis; 10 % of the returns are outliers, uniform in the cone out to R_l. Proximity to
the true surface within R_h; neighbours within R_h; broadcasts delivered within R_c one step later.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np
import pytest

from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.missions.p000_capture.fsw import payload as pl
from swarmhil.missions.p000_capture.fsw import quaternion as quat
from swarmhil.missions.p000_capture.fsw.controller import CaptureController
from swarmhil.missions.p000_capture.contract import CaptureParams
from swarmhil.missions.p000_capture.fsw.sensing import CaptureSensing
from swarmhil.claims.check import claim_failures
from swarmhil.missions.p000_capture.contract import Ellipsoid, signed_distance, surface_frame, surface_landmarks

N_RADPS = float(np.sqrt(3.986004418e14 / 6878137.0 ** 3))  # 500 km circular LEO
SETTLE_S = 20.0  # estimate errors are scored for agents in chase at least this long
SAFETY_DISTANCE_M = 0.5  # no collision: pair distance stays above this (chosen: 8U CubeSat ~0.35 m)


@dataclass
class Packet:
    src: str
    type: str
    payload: bytes
    sent_t: float


@dataclass
class Target:
    semi_axes_m: np.ndarray
    velocity_mps: np.ndarray = field(default_factory=lambda: np.array([0.01, 0.01, 0.0]))
    spin_axis: np.ndarray = field(default_factory=lambda: np.array([0.2, 0.1, 1.0]))
    spin_radps: float = np.radians(0.72)

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        return self.velocity_mps * t, quat.to_dcm(quat.from_axis_angle(self.spin_axis, self.spin_radps * t))

    def ellipsoid(self, t: float) -> Ellipsoid:
        c, rot = self.pose(t)
        return Ellipsoid(c, rot, self.semi_axes_m)


def cw_rhs(r: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1–2 for (N, 3) arrays."""
    n = N_RADPS
    acc = np.stack([3 * n * n * r[:, 0] + 2 * n * v[:, 1], -2 * n * v[:, 0], -n * n * r[:, 2]], axis=1)
    return v, acc + a


def rk4_cw(r: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    k1r, k1v = cw_rhs(r, v, a)
    k2r, k2v = cw_rhs(r + 0.5 * dt * k1r, v + 0.5 * dt * k1v, a)
    k3r, k3v = cw_rhs(r + 0.5 * dt * k2r, v + 0.5 * dt * k2v, a)
    k4r, k4v = cw_rhs(r + dt * k3r, v + dt * k3v, a)
    return r + dt / 6 * (k1r + 2 * k2r + 2 * k3r + k4r), v + dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)


def attitude_step(q: np.ndarray, w: np.ndarray, tau: np.ndarray, j: np.ndarray, dt: float,
                  sub: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3–4: RK4 on Euler's equation, exact quaternion update with the mid-step rate. One body
    (q (4,), w and tau (3,)) or N at once (q (N, 4), w and tau (N, 3))."""
    h = dt / sub
    jinv_t, j_t = np.linalg.inv(j).T, np.asarray(j).T
    for _ in range(sub):
        f = lambda x: (tau - np.cross(x, x @ j_t)) @ jinv_t  # noqa: E731
        k1 = f(w)
        k2 = f(w + 0.5 * h * k1)
        k3 = f(w + 0.5 * h * k2)
        k4 = f(w + h * k3)
        w_new = w + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        w_mid = 0.5 * (w + w_new)
        q = (quat.propagate(q, w_mid, h) if np.ndim(q) == 1
             else np.array([quat.propagate(qi, wi, h) for qi, wi in zip(q, w_mid)]))
        w = w_new
    return q, w


def initial_positions(rng: np.random.Generator, n: int, target: Target, r_buffer: float) -> np.ndarray:
    """Uniform in [−10, 10]³, ≥ 2 m apart, outside the buffer shell (NOTES-000)."""
    pts: list[np.ndarray] = []
    ell = target.ellipsoid(0.0)
    while len(pts) < n:
        p = rng.uniform(-10, 10, 3)
        if signed_distance(ell, p) <= r_buffer:
            continue
        if all(np.linalg.norm(p - o) >= 2.0 for o in pts):
            pts.append(p)
    return np.array(pts)


@dataclass
class RunResult:
    min_pair_m: float
    min_surface_m: float
    final_surface_m: np.ndarray
    modes: list[str]
    chase_entry_s: list[float | None]
    state_broadcasts: int
    landmark_packets: int
    state_bytes: int
    landmark_bytes: int
    chase_agent_steps: int
    axes_err: list[float]
    centre_err_m: list[float]
    wall_s: float
    dt_s: float
    final_pointing_deg: list[float]


def run_capture(n_agents: int = 10, semi_axes=(2.6, 1.9, 1.4), duration_s: float = 300.0, dt_s: float = 0.05,
                seed: int = 1, params: dict | None = None, outlier_fraction: float = 0.1) -> RunResult:
    rng = np.random.default_rng(seed)
    p = CaptureParams.from_dict(params or {})
    target = Target(np.array(semi_axes, dtype=float))
    lm_body, nrm_body = surface_landmarks(target.semi_axes_m, 400)
    ids = [f"a{i}" for i in range(n_agents)]
    orbit = OrbitInfo(6878137.0, N_RADPS)
    ctls = [CaptureController(i, orbit, p) for i in ids]
    r = initial_positions(rng, n_agents, target, p.r_buffer_m)
    v = np.zeros((n_agents, 3))
    q = np.array([quat.normalise(rng.normal(size=4)) for _ in ids])
    w = np.zeros((n_agents, 3))
    tau = np.zeros((n_agents, 3))
    j = p.inertia
    half_fov = np.radians(p.fov_full_deg / 2)
    inbox: list[list[Packet]] = [[] for _ in ids]
    res = RunResult(np.inf, np.inf, np.zeros(0), [], [], 0, 0, 0, 0, 0, [], [], 0.0, dt_s, [])
    t0 = time.perf_counter()
    steps = int(round(duration_s / dt_s))
    for k in range(steps):
        t = k * dt_s
        c_t, rot_t = target.pose(t)
        ell = Ellipsoid(c_t, rot_t, target.semi_axes_m)
        lm_w = c_t + lm_body @ rot_t.T
        nrm_w = nrm_body @ rot_t.T
        d = np.linalg.norm(r[:, None, :] - r[None, :, :], axis=2) + np.eye(n_agents) * 1e9
        res.min_pair_m = min(res.min_pair_m, float(d.min()))
        acc = np.zeros((n_agents, 3))
        outbox: list[list[Packet]] = [[] for _ in ids]
        for i, ctl in enumerate(ctls):
            sd, x_s, _ = surface_frame(ell, r[i])
            res.min_surface_m = min(res.min_surface_m, sd)
            bore = quat.rotate(q[i], [1.0, 0, 0])
            rel = lm_w - r[i]
            dist = np.linalg.norm(rel, axis=1)
            vis = ((np.einsum("ij,ij->i", nrm_w, -rel) > 0) & (dist <= p.r_l_m)
                   & (rel @ bore >= np.cos(half_fov) * dist))
            ret = rel[vis] + rng.normal(0, 0.02, (int(vis.sum()), 3))
            n_out = rng.binomial(len(ret), outlier_fraction) if len(ret) else 0
            if n_out:
                dirs = rng.normal(size=(n_out, 3))
                dirs -= np.outer(dirs @ bore, bore)
                dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
                ang = rng.uniform(0, half_fov, n_out)
                u = np.cos(ang)[:, None] * bore + np.sin(ang)[:, None] * dirs
                ret[:n_out] = u * rng.uniform(1.0, p.r_l_m, n_out)[:, None]
            body = quat.rotate(quat.conjugate(q[i]), ret) if len(ret) else np.zeros((0, 3))
            lm_ids = np.flatnonzero(vis)
            lm_ids[:n_out] = -1
            surf = None
            if sd <= p.r_h_m:
                surf = x_s - r[i]
            near = [m for m in range(n_agents) if m != i and d[i, m] <= p.r_h_m]
            sens = CaptureSensing(q[i], w[i], r[i].copy(), v[i].copy(), body, lm_ids, surf)
            obs = Observation(k, t, 0.0, [ids[m] for m in near], r[near] - r[i], v[near] - v[i],
                              extra=sens.to_dict(), isl_rx=inbox[i])
            was_search = ctl.mode == "search"
            cmd = ctl.step(obs, dt_s)
            if not was_search or ctl.mode != "search":
                res.chase_agent_steps += 1
            acc[i] = cmd.accel_mps2
            for tx in cmd.transmissions:
                pkt = Packet(ids[i], tx.type, tx.payload, t)
                if tx.type == pl.STATE_TYPE:
                    res.state_broadcasts += 1
                    res.state_bytes += len(tx.payload)
                else:
                    res.landmark_packets += 1
                    res.landmark_bytes += len(tx.payload)
                for m in range(n_agents):
                    if m != i and d[i, m] <= p.r_c_m:
                        outbox[m].append(pkt)
            tau[i] = cmd.torque_nm
        q, w = attitude_step(q, w, tau, j, dt_s)  # every body's attitude at once (J diagonal: the same bits)
        inbox = outbox
        r, v = rk4_cw(r, v, acc, dt_s)
    t_end = steps * dt_s
    ell = target.ellipsoid(t_end)
    res.final_surface_m = np.array([signed_distance(ell, x) for x in r])
    res.modes = [c.mode for c in ctls]
    res.chase_entry_s = [c.chase_entry_t for c in ctls]
    for i, c in enumerate(ctls):
        if c.est is not None and c.chase_entry_t is not None and c.chase_entry_t <= t_end - SETTLE_S:
            res.axes_err.append(float(np.max(np.abs(c.est.semi_axes_sorted() / np.sort(target.semi_axes_m) - 1))))
            res.centre_err_m.append(float(np.linalg.norm(c.est.centre_m + c.est.velocity_mps * (t_end - c.est.t_s) - ell.centre_m)))
            bore = quat.rotate(q[i], [1.0, 0, 0])
            los = ell.centre_m - r[i]
            res.final_pointing_deg.append(float(np.degrees(np.arccos(np.clip(bore @ los / np.linalg.norm(los), -1, 1)))))
    res.wall_s = time.perf_counter() - t0
    return res


def report(res: RunResult, label: str) -> str:
    every = res.chase_agent_steps
    hz1 = res.chase_agent_steps * res.dt_s / 1.0
    return (f"{label}: wall {res.wall_s:.1f} s; modes {res.modes}; chase entry {[None if x is None else round(x, 1) for x in res.chase_entry_s]}; "
            f"min pair {res.min_pair_m:.2f} m; min surface {res.min_surface_m:.2f} m; final surface "
            f"{np.round(res.final_surface_m, 2).tolist()}; axes err {np.round(res.axes_err, 3).tolist()}; "
            f"centre err {np.round(res.centre_err_m, 2).tolist()}; pointing {np.round(res.final_pointing_deg, 1).tolist()} deg; "
            f"state broadcasts {res.state_broadcasts} ({res.state_bytes} B) vs every step {every} "
            f"(ratio {res.state_broadcasts / max(every, 1):.3f}) vs 1 Hz {hz1:.0f} (ratio {res.state_broadcasts / max(hz1, 1):.2f}); "
            f"landmark packets {res.landmark_packets} ({res.landmark_bytes} B)")


def check_paper_outcome(res: RunResult, min_out_of_search: int, min_settled: int,
                        centre_max_m: float = 0.2) -> None:
    """The paper's claims that carry numbers or a clear yes/no (docs/paper000.md); `centre_max_m`:
    the bound on the worst centre error, chosen per run from its measured value."""
    print(f"worst axes error {max(res.axes_err, default=float('nan')):.4f}, "
          f"worst centre error {max(res.centre_err_m, default=float('nan')):.4f} m")
    assert sum(m != "search" for m in res.modes) >= min_out_of_search, res.modes
    assert res.min_pair_m > SAFETY_DISTANCE_M                      # no collisions (§4.2)
    assert res.min_surface_m > 0.0                                  # nobody inside the true target
    assert len(res.axes_err) >= min_settled                         # agents in chase >= SETTLE_S
    assert max(res.axes_err) < 0.02                                 # semi-axes recovered (Fig. 7)
    assert max(res.centre_err_m) < centre_max_m
    assert res.state_broadcasts < 0.25 * res.chase_agent_steps      # event trigger << every step


def test_closed_loop_ten_agents_capture_case_i() -> None:
    """Case (i), 10 agents, 100 s at dt = 0.1 s (twice the paper's step, for time; the 550 s run at
    0.05 s is the system test), perception every 2 s. Measured (seed 1): 7 agents chase from
    20–34 s, 3 more at ~96 s; axes within 1 %; event broadcasts ≈ 0.12 of every step."""
    res = run_capture(duration_s=100.0, dt_s=0.1, seed=1, params={"perception_period_s": 2.0})
    print(report(res, "case i, 100 s, dt 0.1"))
    # worst centre error measured on an AVX2 machine 0.030 m and 0.039 m (its own kernels and
    # OPENBLAS_CORETYPE=Sandybridge NPY_DISABLE_CPU_FEATURES=X86_V3), and 0.087 m with the initial
    # attitudes normalised by math.hypot instead of BLAS (last bits only: the loop is chaotic,
    # docs/determinism.md): bound 0.15 m, 1.7x the largest (was 0.2 m); worst axes error 1.1-1.3 %
    # against the paper's 2 %
    check_paper_outcome(res, min_out_of_search=7, min_settled=7, centre_max_m=0.15)


@functools.lru_cache(maxsize=1)
def case_i_paper_run() -> RunResult:
    """Case (i) as the paper (10 agents, 550 s at dt = 0.05 s, seed 1), flown once per pytest session:
    two system tests read it, and it is the longest part of their CI time."""
    return run_capture(duration_s=550.0, dt_s=0.05, seed=1)


@pytest.mark.system
@pytest.mark.timeout(1800)  # one 550 s loop: 574 s wall at load ~20 (issue 29; 1222 s before, bench/bench_p000.py)
def test_system_case_i_550s_paper_step() -> None:
    """Case (i) as the paper: 10 agents, 550 s at dt = 0.05 s, governed chase, event trigger."""
    res = case_i_paper_run()
    print(report(res, "case i, 550 s, dt 0.05"))
    check_paper_outcome(res, min_out_of_search=10, min_settled=10)
    assert res.state_broadcasts < res.chase_agent_steps * res.dt_s  # fewer than 1 Hz periodic
    assert sorted(x for x in res.chase_entry_s if x is not None)[-1] < 325.6  # enclosure by Fig. 3(d)
    assert claim_failures("p000.i-event", res) == []  # its docs/paper000.md column (claims/paper000.py)


@pytest.mark.system
@pytest.mark.timeout(3600)  # two 550 s loops (the default 600 s stopped it in the first at load ~15)
def test_system_case_i_periodic_baseline_sends_more() -> None:
    """The same seed with the 1 Hz periodic broadcast: the link carries more state packets."""
    event = case_i_paper_run()
    periodic = run_capture(duration_s=550.0, dt_s=0.05, seed=1, params={"broadcast": "periodic"})
    print(report(event, "event"), report(periodic, "periodic 1 Hz"), sep="\n")
    assert event.state_broadcasts < periodic.state_broadcasts
    assert claim_failures("p000.i-periodic", periodic) == []  # its docs/paper000.md column (claims/paper000.py)


@pytest.mark.system
@pytest.mark.study
def test_system_case_ii_twenty_agents() -> None:
    """Case (ii): 20 agents around the elongated (4.0, 1.3, 1.0) m target, 550 s at 0.05 s."""
    res = run_capture(n_agents=20, semi_axes=(4.0, 1.3, 1.0), duration_s=550.0, dt_s=0.05, seed=1)
    print(report(res, "case ii, 550 s, dt 0.05"))
    check_paper_outcome(res, min_out_of_search=15, min_settled=15)  # NOTES-000 trap 9: a wanderer may stay in search


@pytest.mark.system
@pytest.mark.study
def test_system_literal_chase_law_flies_into_the_target() -> None:
    """NOTES-000 trap 1, shown: eq. 25–26 as printed (no approach governor) under F_max = 0.1 N
    overshoots the slot by metres: an agent ends up inside the true surface (seed 1: docs/paper000.md
    "Paper vs measured", claims/paper000.py)."""
    res = run_capture(duration_s=550.0, dt_s=0.05, seed=1, params={"chase_law": "literal"})
    print(report(res, "literal chase law"))
    assert res.min_surface_m < 0.0


def test_case_result_feeds_every_paper000_claim() -> None:
    """claims/paper000.py reads a run through `case_result`: every claim of a column computes from a
    short run (5 s at 0.1 s, seconds), so a renamed field fails here and not after a 550 s run."""
    from swarmhil.claims.paper000 import CLAIMS, POLICIES, case_result

    run = run_capture(duration_s=5.0, dt_s=0.1, seed=1)
    out = case_result(run)
    assert out["n_agents"] == 10 and out["state_packets"] >= 0
    for c in CLAIMS:
        if c.source in {f"p000.i-{k}" for k in POLICIES}:
            c.compute(out)
    # positive control of the system tests' check: a run that is not the 550 s one misses its row
    bad = {b.split(":")[0] for b in claim_failures("p000.i-event", run)}
    assert {"p000.i-event.entry-last", "p000.i-event.state-packets"} <= bad, bad
