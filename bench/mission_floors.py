"""The compute floors of papers 000, 001, 003 and 004: each mission in one plain numpy loop (issue 29).

    python bench/mission_floors.py deploy/scenarios/servicing-6.toml [--duration 60] [--repeats 3]

What bench/vectorised_floor.py is for paper 002, for the four mission worlds (`[plant] fidelity =
"cw"` or `"inertial"`): the same scenario (initial states, step, duration, per-craft actuator
limits, controller parameters), the same control law and the same dynamics, written as one loop
over arrays of all spacecraft, without nodes, bus, messages, recorder, link model, contact events
or validation. What it shares with the project is the mathematics only: the plant's propagators'
pure functions (the closed-form HCW matrices of plant/dynamics/cw.py; the attitude's RK4 step of
plant/dynamics/attitude.py; the DOP853 tableau and step of plant/dynamics/rk_tableau.py, with the
right-hand side written here: two-body, J2 and drag as in plant/dynamics/absolute_j2.py), and the
flight software's pure functions (paper 000's landmark visibility and returns, GNC-TLS and warm
ellipsoid fits, closest surface points, APF, event trigger and pointing law over arrays; the
Tersoff-Brenner forces of paper 001; the funnel law, Nash CT gradient kernel and relative dynamics
of paper 003; the Lb-DNN forward pass and internal-state RK4 of paper 004). The initial conditions
and the per-craft constants are read, before the loop, from the plant's world and the controllers
as the scenario builds them. Everything a step does between those functions (sensing, the link's
one-step delay and quantised payloads, paper 000's landmark pools, consensus and modes, the layer
latch, the saturations, the actuator limit, the frames, the dV) is written here over arrays; what
is inherently one per spacecraft (paper 000's fits, its spacecraft's random generators) stays so.

`floor(sc)` dispatches on the scenario's controller; each floor returns the loop's wall time, the
total dV and the final positions in the scenario frame, which must agree with the batch run's truth
(tests/test_mission_floors.py; bench/bench_batch_missions.py --floors reports the difference).
Assumed of the scenario, and checked: no sensing noise for papers 001 and 003 (papers 000 and 004
draw theirs as their sensing kinds draw it, from a generator per seed, step and spacecraft), and,
where there is a link, every packet delivered at the next step: no loss, latency or bitrate (so no
queue), no link faults, no Earth occultation (papers 001, 003, 004: no range drop either, the
scenarios' own links). Paper 000's link (capture-10, capture-20: R_c = 9.5 m, latency 0) drops
by range: a packet sent at step k reaches, at step k + 1, every other spacecraft within `range_m`
of its sender at step k (the positions of the truth of step k, as `BatchLink` feeds the link
model), in the order of the senders, each sender's landmarks before its state; the floor checks
that the spacecraft stay far enough from the Earth for no line between them to be occulted.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def _world(sc: Any) -> Any:
    """The plant's world of `sc` as built at step 0 (initial states, limits, rows, frame origin)."""
    from swarmhil.deploy.scenario import plant_config
    from swarmhil.plant.mission_world import MissionWorld

    return MissionWorld(plant_config(sc))


def _controllers(sc: Any) -> list[Any]:
    """Each spacecraft's controller as its agent would build it (read for its constants and initial state)."""
    from swarmhil.agent.catalogue import make_controller
    from swarmhil.agent.controller import OrbitInfo
    from swarmhil.deploy.agent_image import agent_config

    out = []
    for sid in sc.ids:
        c = agent_config(sc, sid)
        o = c["orbit"]
        out.append(make_controller(c["controller"], sid, OrbitInfo(o["semi_major_axis_m"], o["mean_motion_radps"]), c["params"]))
    return out


def _limit_norm(a: np.ndarray, max_mps2: np.ndarray) -> np.ndarray:
    """Rows scaled into |a| <= max (plant/dynamics/limits.py `limit_norm`)."""
    norm = np.sqrt((a * a).sum(1))
    over = norm > max_mps2
    return a * np.where(over, max_mps2 / np.where(over, norm, 1.0), 1.0)[:, None] if over.any() else a


def _result(wall0: float, steps: int, n: int, dv: np.ndarray, pos: np.ndarray) -> dict:
    return {"loop_s": time.perf_counter() - wall0, "steps": steps, "agents": n, "dv_total_mps": float(dv.sum()),
            "position_m": pos}


# ---------------------------------------------------------------------------------------- paper 001


def floor_lattice(sc: Any, steps: int | None = None) -> dict:
    """Paper 001 (tersoff-6): the `relative` sensing ball, the latched layers' gathering laws (far: the
    ballistic CW field; near: the free well; shaping: planar and phase wells), the Tersoff-Brenner
    term of each spacecraft's sensed cluster, the norm saturation, the actuator limit and the exact
    HCW step (missions/p001_lattice/fsw, plant/dynamics/cw.py)."""
    from swarmhil.missions.p001_lattice.contract import TB_GAIN
    from swarmhil.missions.p001_lattice.fsw.tersoff import forces
    from swarmhil.plant.dynamics.cw import transition_matrix, zoh_input_matrix

    w, ctrls = _world(sc), _controllers(sc)
    prm = sc.sensing.get("params", {})
    if any(prm.get(k, 0.0) for k in ("position_noise_m", "velocity_noise_mps", "own_position_noise_m", "own_velocity_noise_mps")):
        raise ValueError("the paper-001 floor has no sensing noise")
    steps = sc.steps if steps is None else steps
    dt, rng_m = sc.step_s, float(prm["range_m"])
    p, tb = ctrls[0].p, ctrls[0].tb
    dock, centre = ctrls[0].dock_m, ctrls[0].centre_m
    n_rad = p.mean_motion_radps
    pos, vel = w.propagator.state()
    n = len(pos)
    umax = w.max_accel_mps2
    if any(m != "norm" for m in w.limit_mode):
        raise ValueError("the paper-001 floor limits by norm")
    phi_t, gam_t = transition_matrix(w.n_radps, dt).T, zoh_input_matrix(w.n_radps, dt).T
    layer = np.zeros(n, dtype=np.int64)  # 0 far, 1 near, 2 shaping (latched)
    unit = TB_GAIN * p.tb_accel_unit_mps2
    dv = np.zeros(n)
    wall0 = time.perf_counter()
    for k in range(steps):
        t = k * dt
        radius = np.sqrt((pos * pos).sum(1))
        layer = np.where(radius < p.r_inner_m, 2, np.where((layer == 0) & ((radius < p.r_middle_m) | (t > p.t_natural_s)), 1, layer))
        g = np.zeros((n, 3))
        far = layer == 0
        if far.any():  # eq. 1-2 (reading): k_g (v_d - v), v_d on the CW arc to the origin at t_desire
            tau = n_rad * (p.t_desire_s - t)
            s, c = np.sin(tau), np.cos(tau)
            phi_rr = np.array([[4.0 - 3.0 * c, 0.0, 0.0], [6.0 * (s - tau), 1.0, 0.0], [0.0, 0.0, c]])
            phi_rv = np.array([[s, 2.0 * (1.0 - c), 0.0], [-2.0 * (1.0 - c), 4.0 * s - 3.0 * tau, 0.0], [0.0, 0.0, s]]) / n_rad
            v_d = -np.linalg.solve(phi_rv, phi_rr @ pos[far].T).T
            g[far] = p.far_gain_ps * (v_d - vel[far]) - (p.damping_ps * vel[far] if p.far_damping else 0.0)
        near = layer == 1
        if near.any():  # eq. 3 + 15
            d = pos[near] - centre
            g[near] = -p.alpha_free_ps2 * d * np.exp(-(d * d).sum(1) / p.k_free_m2)[:, None] - p.damping_ps * vel[near]
        shp = layer == 2
        if shp.any():  # eq. 4, 5 (+ 3) + 15
            dx = pos[shp, 0] - p.x_shift_m
            gs = np.zeros((int(shp.sum()), 3))
            gs[:, 0] = -p.alpha_planar_ps2 * dx * np.exp(-dx * dx / p.k_planar_m2)
            d = pos[shp] - dock
            gs += -p.alpha_phase_ps2 * d * np.exp(-(d * d).sum(1) / p.k_phase_m2)[:, None]
            if p.free_in_shaping:
                d = pos[shp] - centre
                gs += -p.alpha_free_ps2 * d * np.exp(-(d * d).sum(1) / p.k_free_m2)[:, None]
            g[shp] = gs - p.damping_ps * vel[shp]
        # eq. 14: the TB force on each spacecraft from its own sensed cluster (neighbours within the ball)
        rel = pos[None, :, :] - pos[:, None, :]
        vis = (np.sqrt((rel * rel).sum(2)) <= rng_m) & ~np.eye(n, dtype=bool)
        for i in np.flatnonzero(vis.any(1)).tolist():
            cluster = np.vstack([np.zeros((1, 3)), rel[i, vis[i]] / p.side_m])
            g[i] += unit * forces(cluster, tb)[0]
        acc = _limit_norm(_limit_norm(g, p.max_accel_mps2), umax)  # the law's saturation, then the actuator
        dv += np.sqrt((acc * acc).sum(1)) * dt
        out = np.hstack((pos, vel)) @ phi_t + acc @ gam_t  # exact HCW step, acceleration held
        pos, vel = out[:, :3], out[:, 3:]
    return _result(wall0, steps, n, dv, pos)


# ----------------------------------------------------------------------------- inertial dynamics


def _inertial_rhs(w: Any) -> Callable[[np.ndarray], Callable[[float, np.ndarray], np.ndarray]]:
    """(thrust (R, 3) ECI) -> y' = f(t, y) of the world's inertial rows: two-body (+ J2) (+ drag with a
    rotating exponential atmosphere) + thrust (plant/dynamics/inertial.py, absolute_j2.py)."""
    from swarmhil.plant.dynamics.absolute_j2 import _J2_COEFF
    from swarmhil.plant.dynamics.constants import MU_EARTH_M3PS2, OMEGA_EARTH_RADPS, R_EARTH_M

    prop = w.propagator
    j2, drag, atm = prop.j2, prop.drag, prop._atmosphere
    bc = prop.ballistic_coefficient_m2pkg
    if drag and not atm["rotating_atmosphere"]:
        raise ValueError("the inertial floor's atmosphere rotates with the Earth")
    rho0, h0, hs = atm["rho0_kgpm3"], atm["h0_m"], atm["scale_height_m"]

    def make(thrust: np.ndarray) -> Callable[[float, np.ndarray], np.ndarray]:
        def f(_t: float, y: np.ndarray) -> np.ndarray:
            y = y.reshape(-1, 6)
            r, v = y[:, :3], y[:, 3:]
            r2 = (r * r).sum(1)[:, None]
            inv_r2 = 1.0 / r2
            inv_r = np.sqrt(inv_r2)
            mu_r3 = MU_EARTH_M3PS2 * inv_r2 * inv_r
            out = np.empty_like(y)
            out[:, :3] = v
            if j2:
                z = r[:, 2:3]
                kj = _J2_COEFF * (inv_r2 * inv_r2 * inv_r)
                a = (kj * (1.0 - 5.0 * z * z * inv_r2) - mu_r3) * r
                a[:, 2:3] += 2.0 * kj * z
            else:
                a = -mu_r3 * r
            if drag:
                v_rel = v.copy()
                v_rel[:, 0] += OMEGA_EARTH_RADPS * r[:, 1]
                v_rel[:, 1] -= OMEGA_EARTH_RADPS * r[:, 0]
                rho = rho0 * np.exp(-((np.sqrt(r2[:, 0]) - R_EARTH_M) - h0) / hs)
                a = a + (-0.5 * rho * bc * np.sqrt((v_rel * v_rel).sum(1)))[:, None] * v_rel
            out[:, 3:] = a + thrust
            return out.ravel()
        return f

    return make


def _lvlh_rows(r_c: np.ndarray, v_c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Positions of rows r relative to (r_c, v_c), in its LVLH axes (plant/dynamics/frames.py)."""
    from swarmhil.plant.dynamics.frames import lvlh_basis

    return (r - r_c) @ lvlh_basis(r_c, v_c).T


# ---------------------------------------------------------------------------------------- paper 003


def floor_surround(sc: Any, steps: int | None = None) -> dict:
    """Paper 003 (surround-6): the leader's funnel law on the measured target, the servicers' Nash CT
    control (eq. 6, 18-21) each over its own view (the others' x~ and ξ of the last step's packets,
    float32), the sphere centres carried forward from the leader's packet, the Euler step of ξ_i,
    the actuator limits and the inertial plant (DOP853) in the leader's LVLH."""
    from swarmhil.missions.p003_surround.fsw import vectorised
    from swarmhil.missions.p003_surround.fsw.funnel import leader_accel, tt_control
    from swarmhil.missions.p003_surround.fsw.nash import ct_accel
    from swarmhil.missions.p003_surround.fsw.relative_dynamics import natural_rel_accel
    from swarmhil.missions.p003_surround.fsw.controllers import LeaderController, ServicerController
    from swarmhil.plant.bodies import manoeuvre_accel
    from swarmhil.plant.dynamics.constants import MU_EARTH_M3PS2
    from swarmhil.plant.dynamics.frames import eci_to_lvlh, lvlh_vector_to_eci
    from swarmhil.plant.dynamics.rk_tableau import rk_step

    w, ctrls = _world(sc), _controllers(sc)
    prm = sc.sensing.get("params", {})
    if prm.get("position_noise_m", 0.0) or prm.get("velocity_noise_mps", 0.0):
        raise ValueError("the paper-003 floor has no sensing noise")
    lead = next(i for i, c in enumerate(ctrls) if isinstance(c, LeaderController))
    srv = [i for i, c in enumerate(ctrls) if isinstance(c, ServicerController)]
    if len(srv) + 1 != len(ctrls) or {ctrls[i]._kind() for i in srv} != {ctrls[srv[0]]._kind()}:
        raise ValueError("the paper-003 floor flies one leader and servicers that share their game")
    lp, c0 = ctrls[lead].p, ctrls[srv[0]]
    g, slots, d_cg, r_g = c0.g, c0.slots_m, c0.d_cg_m, c0.r_g_m
    own = np.array([ctrls[i].index for i in srv])
    S, G = len(srv), len(d_cg)
    target = next(k for k, b in enumerate(w.prop_bodies) if b.id == prm.get("target_id", "tsat"))
    steps = sc.steps if steps is None else steps
    dt, a_m, n_rad = sc.step_s, c0.orbit.semi_major_axis_m, c0.orbit.mean_motion_radps
    n = len(sc.ids)
    o, off = w._origin_row, w._offset
    if w.command_frame != "lvlh" or any(m != "norm" for m in w.limit_mode) or w.propagator.j2 or w.propagator.drag:
        raise ValueError("the paper-003 floor commands in the leader's LVLH, limited by norm, on two-body orbits")
    umax = w.max_accel_mps2
    manoeuvres = [b.motion.manoeuvres for b in w.prop_bodies]
    rhs = _inertial_rhs(w)
    r, v = w.propagator.state()
    y = np.hstack((r, v))
    # each servicer's view: its own row fresh, the others as last received (the packets of the step before)
    x_err = np.zeros((S, S, 6))
    xi = np.array([ctrls[i].xi for i in srv])
    tt = None  # the leader's last packet, as received: (accel, q_TL, q'_TL) float32, sent at t_tt
    t_tt = 0.0
    f32 = np.float32
    thrust_o = np.zeros(3)
    dv = np.zeros(n)
    rows = np.arange(S)
    wall0 = time.perf_counter()
    for k in range(steps):
        t = k * dt
        # the truth in the leader's LVLH (its last thrust turning the frame, frames.py)
        r_c, v_c = y[o, :3], y[o, 3:]
        inv_r2 = 1.0 / float(r_c @ r_c)
        a_c = -(MU_EARTH_M3PS2 * inv_r2 * np.sqrt(inv_r2)) * r_c + thrust_o  # two-body (checked above)
        p_all, v_all = eci_to_lvlh(r_c, v_c, y[:, :3], y[:, 3:], a_c)
        pos, vel = p_all[off:], v_all[off:]
        # leader: funnel target tracking (eq. 15-17) on q_TL, its hold the step
        q_tl, v_tl = pos[n + target] - pos[lead], vel[n + target] - vel[lead]
        if np.sqrt(q_tl @ q_tl) > prm.get("range_m", 1e9):
            raise ValueError("the paper-003 floor's leader always sees the target")
        u_l = tt_control(q_tl, v_tl, t, lp, lp.sample_s if k == 0 else t - (k - 1) * dt)[0]  # the measured hold
        acc = np.zeros((n, 3))
        acc[lead] = leader_accel(u_l, lp)
        # servicers: measured q_Li, the CT gradient over each one's view, eq. 6
        me_p, me_v = pos[srv] - pos[lead], vel[srv] - vel[lead]
        x_err[rows, own, :3] = me_p - slots[own]
        x_err[rows, own, 3:] = me_v
        if tt is None:
            centres = np.full((S, G, 3), 1e12)
        else:
            centres = np.broadcast_to(tt[1] + tt[2] * (t - t_tt) + d_cg, (S, G, 3))
        grad, rate = vectorised.grad_and_xi_rate(x_err, xi, slots, centres, r_g, own, g)
        m = g.mass_kg
        u_ct = m * ct_accel(grad, g)
        u_id = -m * natural_rel_accel(me_p, me_v, a_m, n_rad) if g.cancel_natural else np.zeros((S, 3))
        u_sync = m * (tt[0] if tt is not None else np.zeros(3))
        if g.saturate == "sum":
            u = _limit_norm(u_sync + u_ct + u_id, np.full(S, g.max_thrust_n))
        else:
            u = u_sync + _limit_norm(u_ct + u_id, np.full(S, g.max_thrust_n))
        acc[srv] = u / m
        rate[:, :3] = _limit_norm(rate[:, :3], np.full(S, g.xi_rate_cap_mps))
        xi[rows, own] = xi[rows, own] + (t - (k - 1) * dt if k else 0.0) * rate
        # the packets of this step, read at the next: every servicer's (x~_i, ξ_i), the leader's TT
        sent_x, sent_xi = x_err[rows, own].astype(f32), xi[rows, own].astype(f32)
        for s in range(S):
            others = rows != s
            x_err[s, own[others]] = sent_x[others]
            xi[s, own[others]] = sent_xi[others]
        tt, t_tt = (acc[lead].astype(f32).astype(float), q_tl.astype(f32).astype(float),
                    v_tl.astype(f32).astype(float)), t
        # plant: limits, dV, the commands and the target's manoeuvre in the leader's LVLH -> ECI, DOP853
        acc = _limit_norm(acc, umax)
        dv += np.sqrt((acc * acc).sum(1)) * dt
        body = np.array([manoeuvre_accel(mv, t) for mv in manoeuvres]).reshape(-1, 3)
        thrust = np.zeros_like(y[:, :3])
        thrust[off:] = lvlh_vector_to_eci(r_c, v_c, np.vstack([acc, body]))
        thrust_o = thrust[o].copy()
        y = rk_step(rhs(thrust), t, y.ravel(), dt).reshape(-1, 6)
    return _result(wall0, steps, n, dv, _lvlh_rows(y[o, :3], y[o, 3:], y[off:off + n, :3]))


# ---------------------------------------------------------------------------------------- paper 004


def floor_servicing(sc: Any, steps: int | None = None) -> dict:
    """Paper 004 (servicing-6): the partial measurements (eq. 9-10, noise drawn as the `p004-partial`
    kind draws it), eta_i (eq. 12), the RK4 of the six internal states over the hold (eqs. 25, 26, 28:
    the neighbours' u_j and float32 theta_j of the last step's packets), the Lb-DNN and eq. 27, the
    actuator limit and the inertial plant (two-body + J2 + drag, DOP853), commands in ECI."""
    from swarmhil.missions.p004_lbdnn.fsw import vectorised
    from swarmhil.missions.p004_lbdnn.sense import measurement_noise
    from swarmhil.plant.dynamics.rk_tableau import rk_step

    w, ctrls = _world(sc), _controllers(sc)
    prm = sc.sensing.get("params", {})
    std = float(prm.get("noise_std_m", np.sqrt(0.5)))
    law = ctrls[0].law()
    if any(c.law() != law for c in ctrls) or w.command_frame != "eci":
        raise ValueError("the paper-004 floor flies servicers that share one law, commanding in ECI")
    cfgs = [c.cfg for c in ctrls]
    n = len(cfgs)
    index = {sid: i for i, sid in enumerate(sc.ids)}
    defunct = n + next(k for k, b in enumerate(w.prop_bodies) if b.id == prm.get("defunct_id", "defunct"))
    nb = [np.array([index[j] for j in c.neighbours], dtype=np.int64) for c in cfgs]
    n_nb = np.array([len(x) for x in nb])
    ctc = np.array([c.ctc for c in cfgs])
    cm = [c.c_matrix for c in cfgs]
    clip = [c.max_accel_mps2 for c in cfgs]
    gn = law.gains
    seed = int(sc.seed)
    steps = sc.steps if steps is None else steps
    dt = sc.step_s
    o, off = w._origin_row, w._offset
    umax = w.max_accel_mps2[:, None]
    if any(m != "per_axis" for m in w.limit_mode) or any(b.motion.manoeuvres for b in w.prop_bodies):
        raise ValueError("the paper-004 floor limits per axis, and its defunct craft does not manoeuvre")
    rhs = _inertial_rhs(w)
    r, v = w.propagator.state()
    y = np.hstack((r, v))
    x = np.zeros((n, 9 + ctrls[0].theta.size))  # (eta_hat, zeta_hat, nu, theta_hat) per servicer
    x[:, 9:] = [c.theta for c in ctrls]
    eta_prev, u_prev = np.zeros((n, 3)), np.zeros((n, 3))
    sent_u, sent_theta = None, None  # the last step's packets: u_j (float64), theta_j (float32)
    dv = np.zeros(n)
    wall0 = time.perf_counter()
    for k in range(steps):
        t = k * dt
        q = y[off:, :3]
        eta = np.zeros((n, 3))
        for i, c in enumerate(cfgs):  # eq. 9, 10, 12 (the sensing kind's draws, per servicer and step)
            d_noise, y_noise = measurement_noise(seed, k, i, len(nb[i]), cm[i].shape[0], std)
            eta[i] = (q[nb[i]] - q[i] + d_noise).sum(axis=0)
            if c.b:
                eta[i] += cm[i].T @ (cm[i] @ (q[defunct] - q[i]) + y_noise)
        if k == 0:
            x[:, 6:9] = (gn.k3 + gn.k4) * eta  # nu(0): rho(0) = 0
        else:
            coupling = np.stack([(sent_u[nb[i]] - u_prev[i]).sum(0) for i in range(n)]) - (ctc @ u_prev[:, :, None])[:, :, 0]
            theta_nb = sent_theta[np.stack(nb)] if len(set(n_nb.tolist())) == 1 else None
            if theta_nb is None:
                raise ValueError("the paper-004 floor's graph is regular (the ring)")
            x = vectorised.propagate(x, t - (k - 1) * dt, eta_prev, coupling, theta_nb, n_nb, law)
        eta_hat, zeta_hat, nu = x[:, 0:3], x[:, 3:6], x[:, 6:9]
        phi = vectorised.forward(np.concatenate([eta, zeta_hat], axis=1), x[:, 9:], jacobian=False)[0] if law.use_network else 0.0
        eta_tilde = eta - eta_hat
        rho = -(gn.k3 + gn.k4) * eta_tilde + nu
        u = phi + gn.k2 * (gn.k1 * eta + zeta_hat - gn.k3 * eta_tilde - rho)  # eq. 27
        if clip[0] is not None:
            u = np.clip(u, -np.array(clip)[:, None], np.array(clip)[:, None])
        eta_prev, u_prev = eta, u
        sent_u, sent_theta = u, x[:, 9:].astype(np.float32).astype(float)
        acc = u.clip(-umax, umax)
        dv += np.sqrt((acc * acc).sum(1)) * dt
        thrust = np.zeros_like(y[:, :3])
        thrust[off:off + n] = acc
        y = rk_step(rhs(thrust), t, y.ravel(), dt).reshape(-1, 6)
    return _result(wall0, steps, n, dv, _lvlh_rows(y[o, :3], y[o, 3:], y[off:off + n, :3]))


# ---------------------------------------------------------------------------------------- paper 000


def _quantised_landmarks(t_s: float, share_m: np.ndarray) -> tuple[float, np.ndarray]:
    """A `landmarks` packet as its receivers read it (fsw/payload.py): t as float32, the points rounded
    to millimetres, those beyond the int16 range left out, at most 255."""
    mm = np.round(np.asarray(share_m, dtype=float).reshape(-1, 3) * 1000.0)
    mm = mm[np.all(np.abs(mm) <= 32767, axis=1)][:255].astype("<i2")
    return float(np.float32(t_s)), mm.astype(float) / 1000.0


def _quantised_shapes(m: np.ndarray) -> np.ndarray:
    """The shape matrices (N, 3, 3) of `state` packets as their receivers read them: the upper
    triangle in float32, mirrored (fsw/payload.py `decode_state`: m + triu(m, 1)ᵀ)."""
    up = np.triu(m).astype(np.float32).astype(float)
    return up + np.swapaxes(np.triu(up, 1), -1, -2)


class _CaptureFits:
    """Each spacecraft's landmark pool and GNC-TLS / warm fit (paper 000 §3.2.2; the flight
    software's `_fit`, missions/p000_capture/fsw/controller.py), per spacecraft: the fits are
    inherently one per agent. Holds the own estimates (arrays) and the settle history."""

    def __init__(self, n: int, p: Any, gnc: Any, rngs: list[np.random.Generator]) -> None:
        self.p, self.gnc, self.rngs = p, gnc, rngs
        self.pool: list[list[tuple[float, np.ndarray]]] = [[] for _ in range(n)]
        self.has_own = np.zeros(n, dtype=bool)
        self.own_t = np.zeros(n)
        self.own_c, self.own_v, self.own_m = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3))
        self.history: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.settled = np.zeros(n, dtype=bool)
        self.fits = 0

    def fit(self, i: int, t: float, r: np.ndarray, est: tuple[float, np.ndarray, np.ndarray] | None) -> None:
        """Spacecraft i's fit at t from its pool (`est`: its estimate before this step's consensus)."""
        from swarmhil.missions.p000_capture.contract import Ellipsoid, signed_distance
        from swarmhil.missions.p000_capture.fsw.estimate import TargetEstimate, alpha_beta
        from swarmhil.missions.p000_capture.fsw.gnc_tls import gnc_tls_fit, warm_fit
        from swarmhil.missions.p000_capture.fsw.limits import norm3

        p, gnc = self.p, self.gnc
        pool = self.pool[i] = [(tp, pts) for tp, pts in self.pool[i] if t - tp <= p.perception_period_s]
        vel = est[2] if est is not None else np.zeros(3)
        pts = np.concatenate([q + vel * (t - tp) for tp, q in pool]) if pool else np.zeros((0, 3))
        if len(pts) < p.fit_min_points:
            return
        if len(pts) > p.fit_max_points:
            pts = pts[self.rngs[i].permutation(len(pts))[: p.fit_max_points]]
        fit = None
        if self.has_own[i]:  # warm fit from the own estimate while it explains most points
            try:
                prev = Ellipsoid.from_shape_matrix(self.own_c[i] + self.own_v[i] * (t - self.own_t[i]), self.own_m[i])
                fit = warm_fit(pts, prev, gnc)
                if fit.inliers.mean() < p.track_min_inlier_fraction:
                    fit = None
            except ValueError:
                fit = None
        try:
            fit = fit or gnc_tls_fit(pts, gnc)
        except ValueError:
            return
        ell = fit.ellipsoid
        self.fits += 1
        if not (np.all(ell.semi_axes_m > 0.2) and np.all(ell.semi_axes_m < 10.0)
                and fit.inliers.sum() >= p.fit_min_points // 2 and signed_distance(ell, r) > 0.0):
            return
        if est is not None and self.has_own[i]:  # innovation gate on the centre
            if norm3(ell.centre_m - (est[1] + est[2] * (t - est[0]))) > 1.0:
                return
        prev_own = TargetEstimate(self.own_t[i], self.own_c[i], self.own_v[i], self.own_m[i], True) if self.has_own[i] else None
        c, v = alpha_beta(prev_own, t, ell.centre_m)
        self.has_own[i], self.own_t[i], self.own_c[i], self.own_v[i], self.own_m[i] = True, t, c, v, ell.shape_matrix
        h = self.history[i] = (self.history[i] + [np.sort(ell.semi_axes_m)])[-p.dock_settle_fits:]
        if len(h) >= p.dock_settle_fits:
            a = np.array(h)
            self.settled[i] = bool(np.all((a.max(axis=0) - a.min(axis=0)) <= p.dock_axes_tol * a.mean(axis=0)))
        else:
            self.settled[i] = False


def floor_capture(sc: Any, steps: int | None = None) -> dict:
    """Paper 000 (capture-10, capture-20): the `p000-landmarks` sensing (visibility of the target's
    landmarks, the noise drawn as the kind draws it, per (seed, step, spacecraft), only where a fit
    uses it), each spacecraft's landmark pool and GNC-TLS / warm fit (per spacecraft), the packets of
    the broadcast ISL (landmarks in millimetres, estimates in float32, read one step later by every
    spacecraft within the link's range at the sending step), the consensus of eq. 30, the modes,
    the search forces (bounce, random walk, the sensed surface's buffer), the APF, the chase PD
    toward the buffer slot under the event trigger (eq. 26-29), the pointing and search torques,
    the saturations, and the plant: the exact HCW step, the actuator and torque limits, and the
    attitude's RK4 (missions/p000_capture/, plant/dynamics/cw.py and attitude.py)."""
    from swarmhil.deploy.scenario import plant_config
    from swarmhil.link.model import parse_link_config
    from swarmhil.link.node import enabled as channel_enabled
    from swarmhil.missions.p000_capture import contract as cc
    from swarmhil.missions.p000_capture.contract import Ellipsoid, dot_rows, surface_frames
    from swarmhil.missions.p000_capture.fsw import quaternion as quat
    from swarmhil.missions.p000_capture.fsw.apf import apf_forces
    from swarmhil.missions.p000_capture.fsw.attitude import _cross_rows, desired_attitudes, pointing_torques
    from swarmhil.missions.p000_capture.fsw.modes import random_force
    from swarmhil.missions.p000_capture.fsw.trigger import fires_rows
    from swarmhil.missions.p000_capture.sense import (NOISE_TAG, P000Params, inertial_to_cw, landmark_returns,
                                                      visible_landmarks)
    from swarmhil.plant.dynamics.attitude import quat_from_axis_angle, quat_multiply, rk4_attitude_step
    from swarmhil.plant.dynamics.cw import transition_matrix, zoh_input_matrix
    from swarmhil.plant.dynamics.limits import limit_norm

    w, ctrls = _world(sc), _controllers(sc)
    p, c0 = ctrls[0].p, ctrls[0]
    if any(c.p != p or c.trigger != c0.trigger or c.gnc != c0.gnc for c in ctrls) or p.broadcast != "event":
        raise ValueError("the paper-000 floor flies spacecraft that share one CaptureParams, broadcasting on the event trigger")
    if sc.decision_period_steps != 1 or getattr(sc, "faults", None):
        raise ValueError("the paper-000 floor decides every step, without faults")
    if not channel_enabled(sc, {}):
        raise ValueError("the paper-000 floor flies with its [link]")
    link = parse_link_config(sc.sections["link"], sc.source, sc.seed)
    if link.latency_s or link.loss_probability or link.bitrate_bps:
        raise ValueError("the paper-000 floor's link delivers every packet at the next step (no latency, loss or bitrate)")
    if w.attitude is None or len(w.att_index) != len(sc.ids) or any(m != "norm" for m in w.limit_mode) or w.prop_bodies:
        raise ValueError("the paper-000 floor flies attitude for every spacecraft, limited by norm, and no propagated body")
    sp = P000Params.model_validate(sc.sensing.get("params", {}))
    pc = plant_config(sc)
    body = next(b for b in pc.bodies if b.id == sp.target_id)
    m = body.motion
    if w.body_faults or m.kind != "kinematic":
        raise ValueError("the paper-000 floor's target drifts and spins freely")
    semi_axes = np.asarray(body.shape.semi_axes_m, float)
    lm_body, nrm_body = cc.surface_landmarks(semi_axes, sp.landmarks)
    t_p0, t_v0 = np.asarray(m.position_m, float), np.asarray(m.velocity_mps, float)
    spin_axis, spin_rate, t_q0 = np.asarray(m.spin_axis), m.spin_rate_radps, np.concatenate([m.attitude_q[1:], m.attitude_q[:1]])
    origin = t_p0
    prox_margin = 1e-6 + float(semi_axes.max())
    seed = int(sc.seed)
    steps = sc.steps if steps is None else steps
    dt, n = sc.step_s, len(sc.ids)
    n_world, n_ctrl = float(w.n_radps), c0.n
    # the Earth's centre is at (-a, 0, 0) of the frame: no line between spacecraft within this box is occulted
    clear_box_m = (w.a_m - link.earth_radius_m - link.grazing_altitude_m) / 3.0 ** 0.5 if link.occultation else np.inf
    phi_t, gam_t = transition_matrix(w.n_radps, dt).T, zoh_input_matrix(w.n_radps, dt).T
    state = np.hstack(w.propagator.state())
    att = w.attitude
    qa, wa = att.state()
    inertia, inertia_inv, tmax = att.inertia_kgm2, att._inertia_inv, att.max_torque_nm
    umax = w.max_accel_mps2
    e_max = p.approach_speed_mps * p.k_v / p.k_p if p.chase_law == "governed" else None
    scan = np.array([0.0, 0.0, np.radians(p.scan_rate_dps)]) if p.search_attitude == "scan" else np.zeros(3)
    fitter = _CaptureFits(n, p, c0.gnc, [c.rng for c in ctrls])
    rngs = fitter.rngs
    mode = np.zeros(n, dtype=np.int64)  # 0 search, 1 chase, 2 dock
    last_fit_t = np.full(n, -np.inf)
    has_est = np.zeros(n, dtype=bool)
    est_t, est_c, est_v, est_m = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3))
    # the principal axes of each estimate's shape matrix, recomputed where the matrix's bits change
    key_m = np.full((n, 3, 3), np.nan)
    ell_ok, ell_rot, ell_axes = np.zeros(n, dtype=bool), np.zeros((n, 3, 3)), np.ones((n, 3))
    # the neighbours' estimates as received (receiver, source), and the order each receiver first heard them
    nb_has, nb_rank = np.zeros((n, n), dtype=bool), np.zeros((n, n), dtype=np.int64)
    nb_t, nb_c, nb_v, nb_m = np.zeros((n, n)), np.zeros((n, n, 3)), np.zeros((n, n, 3)), np.zeros((n, n, 3, 3))
    rnd_force, rnd_t = np.zeros((n, 3)), np.full(n, -np.inf)
    has_rk, r_k, v_k = np.zeros(n, dtype=bool), np.zeros((n, 3)), np.zeros((n, 3))
    held = np.zeros((n, 3))
    # the last step's packets: who sent a state / landmarks, what, and who was within range
    reach = np.zeros((n, n), dtype=bool)
    sent_state = np.zeros(n, dtype=bool)
    sent = (np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3)))
    sent_lm: list[tuple[float, np.ndarray] | None] = [None] * n
    eye = np.eye(n, dtype=bool)
    rows = np.arange(n)
    big = np.iinfo(np.int64).max
    f_thr, m_kg = p.f_thr_n, p.mass_kg
    own_weight = 0.8  # the own direct fit's weight in the consensus (CaptureController._perceive)
    dv = np.zeros(n)
    wall0 = time.perf_counter()
    for k in range(steps):
        t = k * dt
        pos, vel = state[:, :3], state[:, 3:]
        # --- the sensing kind's truth: the target's pose and landmarks, the craft's CW attitudes, neighbours
        q_t = quat_multiply(quat_from_axis_angle(spin_axis, spin_rate * t), t_q0)
        rot_t = cc.dcm(np.concatenate([q_t[3:], q_t[:3]]))
        p_t = t_p0 + t_v0 * t
        lm_t, nrm_t = p_t + lm_body @ rot_t.T, nrm_body @ rot_t.T
        q_cw = inertial_to_cw(np.concatenate([qa[:, 3:], qa[:, :3]], axis=1), n_world, t)
        rot_cw = cc.dcm(q_cw)
        diff = pos[None, :, :] - pos[:, None, :]
        near = (np.linalg.norm(diff, axis=2) <= sp.neighbour_range_m) & ~eye
        true_ell = cc.Ellipsoid(p_t, rot_t, semi_axes)
        rel_lm = lm_t[None, :, :] - pos[:, None, :]
        vis = visible_landmarks(rel_lm, nrm_t, rot_cw[:, :, 0], sp)
        detected = vis.sum(axis=1) >= p.detect_min_returns
        r, v = pos - origin, vel
        # --- packets of the last step, in the order of their senders
        got = reach & sent_state[:, None]  # (source, receiver)
        received = got.any(axis=0)
        if received.any():
            new = got.T  # (receiver, source)
            nb_rank = np.where(new & ~nb_has, k * n + rows[None, :], nb_rank)
            nb_has |= new
            nb_t = np.where(new, sent[0][None, :], nb_t)
            nb_c = np.where(new[:, :, None], sent[1][None], nb_c)
            nb_v = np.where(new[:, :, None], sent[2][None], nb_v)
            nb_m = np.where(new[:, :, None, None], sent[3][None], nb_m)
        for j in [j for j in range(n) if sent_lm[j] is not None]:
            for i in np.flatnonzero(reach[j]).tolist():
                fitter.pool[i].append(sent_lm[j])  # type: ignore[arg-type]
        sent_lm = [None] * n
        # --- perception at 1 Hz: the own returns (noise drawn here only), pooled, shared and fitted
        for i in np.flatnonzero(detected & (t - last_fit_t >= p.perception_period_s - 1e-9)).tolist():
            ret, _ = landmark_returns(np.random.default_rng([seed, NOISE_TAG, k, i]), rel_lm[i], nrm_t, rot_cw[i][:, 0],
                                      sp, vis[i])
            lm = r[i] + (ret @ rot_cw[i]).reshape(-1, 3) @ quat.to_dcm(q_cw[i]).T
            fitter.pool[i].append((t, lm))
            sent_lm[i] = _quantised_landmarks(t, lm[rngs[i].permutation(len(lm))[: p.landmarks_per_packet]])
            fitter.fit(i, t, r[i], (est_t[i], est_c[i], est_v[i]) if has_est[i] else None)
            last_fit_t[i] = t
        # --- consensus (eq. 30): the own fresh fit first (0.8 when others), then the fresh neighbours as first heard
        own_ok = fitter.has_own & (t - fitter.own_t <= p.estimate_max_age_s)
        fresh = nb_has & (t - nb_t <= p.estimate_max_age_s)
        count = fresh.sum(axis=1)
        total = count + own_ok
        if total.any():
            order = np.argsort(np.hstack([np.where(own_ok, -1, big)[:, None], np.where(fresh, nb_rank, big)]), axis=1,
                               kind="stable")
            ts = np.take_along_axis(np.hstack([fitter.own_t[:, None], nb_t]), order, axis=1)
            cs = np.take_along_axis(np.concatenate([fitter.own_c[:, None], nb_c], axis=1), order[:, :, None], axis=1)
            vs = np.take_along_axis(np.concatenate([fitter.own_v[:, None], nb_v], axis=1), order[:, :, None], axis=1)
            ms = np.take_along_axis(np.concatenate([fitter.own_m[:, None], nb_m], axis=1), order[:, :, None, None], axis=1)
            with np.errstate(divide="ignore"):
                w_nb = np.where(own_ok & (count > 0), (1.0 - own_weight) / count, 1.0 / total)
            w_first = np.where(own_ok & (count > 0), own_weight, w_nb)
            c_sum, v_sum, m_sum = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3))
            for s in range(int(total.max())):
                on = s < total
                ws = np.where(on, w_first if s == 0 else w_nb, 0.0)
                c_sum = c_sum + np.where(on[:, None], ws[:, None] * (cs[:, s] + vs[:, s] * (t - ts[:, s])[:, None]), 0.0)
                v_sum = v_sum + np.where(on[:, None], ws[:, None] * vs[:, s], 0.0)
                m_sum = m_sum + np.where(on[:, None, None], ws[:, None, None] * ms[:, s], 0.0)
            upd = total > 0
            had_est = has_est.copy()
            est_t = np.where(upd, t, est_t)
            est_c, est_v = np.where(upd[:, None], c_sum, est_c), np.where(upd[:, None], v_sum, est_v)
            est_m = np.where(upd[:, None, None], m_sum, est_m)
            has_est |= upd
        else:
            had_est = has_est.copy()
        changed = has_est & (est_m.view(np.int64) != key_m.view(np.int64)).reshape(n, 9).any(axis=1)
        if changed.any():
            ch = np.flatnonzero(changed)
            sym = 0.5 * (est_m[ch] + np.swapaxes(est_m[ch], 1, 2))
            for kk, i in enumerate(ch.tolist()):
                eig, vec = np.linalg.eigh(sym[kk])
                ell_ok[i] = eig[0] > 0.0
                if ell_ok[i]:
                    ell_rot[i], ell_axes[i] = vec, eig ** -0.5
            key_m[ch] = est_m[ch]
        flies = has_est & ell_ok
        ell_c = est_c + est_v * (t - est_t)[:, None]
        sd, x_s, nrm = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3))
        fl = np.flatnonzero(flies)
        if len(fl):
            sd[fl], x_s[fl], nrm[fl] = surface_frames([Ellipsoid(ell_c[i], ell_rot[i], ell_axes[i]) for i in fl.tolist()], r[fl])
        # --- modes (Events 1-3)
        slot = x_s + p.r_buffer_m * nrm
        gap = r - slot
        at_slot = flies & (np.sqrt(dot_rows(gap, gap)) < p.dock_slot_tol_m)
        old = mode
        mode = np.where((old == 0) & (detected | received), 1, np.where((old == 1) & fitter.settled & at_slot, 2, old))
        mode = np.where((mode != 0) & ~flies & (old == 0), 0, mode)
        entered = (old == 0) & (mode != 0)
        # --- forces: APF, then search (bounce, random walk, the sensed surface's buffer) or chase (held PD + buffer)
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.add.accumulate(near.sum(axis=1), out=offsets[1:])
        ii, jj = np.nonzero(near)
        f_col = apf_forces(pos[jj] - pos[ii], offsets, p.k_r, p.r_h_m)
        force = np.zeros((n, 3))
        searching = (mode == 0) | ~flies
        if searching.any():
            for i in np.flatnonzero(searching & (t - rnd_t >= p.random_redraw_s)).tolist():
                rnd_force[i], rnd_t[i] = random_force(rngs[i], p.random_alpha, f_thr), t
            srch = np.flatnonzero(searching)
            rs = r[srch]
            fs = np.where(rs > p.search_box_m, -f_thr, np.where(rs < -p.search_box_m, f_thr, 0.0)) + rnd_force[srch] + f_col[srch]
            # the proximity return of the true surface, within R_h of it (only rows whose centre distance
            # allows it: the surface is at most the largest semi-axis from the centre)
            off_c = pos[srch] - p_t
            cand = np.flatnonzero(np.sqrt(dot_rows(off_c, off_c)) <= sp.proximity_range_m + prox_margin)
            if len(cand):
                t_sd, t_xs, _ = surface_frames([true_ell] * len(cand), pos[srch[cand]])
                prox = cand[t_sd <= sp.proximity_range_m]
                surf = t_xs[t_sd <= sp.proximity_range_m] - pos[srch[prox]]
                d = np.sqrt(dot_rows(surf, surf))
                fs[prox] = fs[prox] + _buffer_rows(d, -surf / np.maximum(d, 1e-9)[:, None], v[srch[prox]], p)
            force[srch] = fs
        chasing = ~searching
        if chasing.any():
            ch = np.flatnonzero(chasing)
            fired = np.zeros(n, dtype=bool)
            rk_rows = np.flatnonzero(has_rk)
            if len(rk_rows):
                fired[rk_rows] = fires_rows(t, r_k[rk_rows], v_k[rk_rows], r[rk_rows], v[rk_rows], n_ctrl, c0.trigger)
            due = ch[(entered | ~had_est | ~has_rk | fired)[ch]]
            if len(due):
                e = r[due] - slot[due]
                if e_max is not None:
                    en = np.sqrt(dot_rows(e, e))
                    over = en > e_max
                    e[over] = e[over] * (e_max / en[over])[:, None]
                held[due] = -p.k_p * e - p.k_v * (v[due] - est_v[due])
                has_rk[due], r_k[due], v_k[due] = True, r[due], v[due]
                sent_state[:] = False
                sent_state[due] = True
                sent = (np.float32(est_t).astype(float), est_c.astype(np.float32).astype(float),
                        est_v.astype(np.float32).astype(float), _quantised_shapes(est_m))
            else:
                sent_state[:] = False
            force[ch] = held[ch] + f_col[ch] + _buffer_rows(sd[ch], nrm[ch], v[ch] - est_v[ch], p)
        else:
            sent_state[:] = False
        fn = np.sqrt(dot_rows(force, force))
        over = fn > p.force_max_n
        force[over] = force[over] * (p.force_max_n / fn[over])[:, None]
        acc = force / m_kg
        # --- torques: pointing at the estimated centre (eq. 15-18) or the search's rate control
        torque = _cross_rows(wa, p.inertia_kgm2 * wa) - p.k_w * (wa - scan)
        tn = np.sqrt(dot_rows(torque, torque))
        over = tn > p.torque_max_nm
        torque[over] = torque[over] * (p.torque_max_nm / tn[over])[:, None]
        if chasing.any():
            ch = np.flatnonzero(chasing)
            torque[ch] = pointing_torques(q_cw[ch], wa[ch], desired_attitudes(ell_c[ch] - r[ch]), p.inertia_kgm2, p.k_q,
                                          p.k_w, p.torque_max_nm)
        # --- the link: this step's packets reach, at the next, every craft within range now
        if not np.abs(pos).max() < clear_box_m:
            raise ValueError("the paper-000 floor's spacecraft stay where no Earth occultation cuts the link")
        reach = (np.sqrt(np.add.reduce(diff * diff, axis=2)) <= link.range_m) & ~eye
        # --- plant: limits, dV, exact HCW step, attitude RK4
        a = limit_norm(acc, umax)
        dv += np.linalg.norm(a, axis=1) * dt
        state = state @ phi_t + a @ gam_t
        tau = limit_norm(torque, tmax) if tmax is not None else torque
        qa, wa = rk4_attitude_step(qa, wa, inertia, inertia_inv, tau, dt)
    out = _result(wall0, steps, n, dv, state[:, :3])
    out["fits"] = fitter.fits
    return out


def _buffer_rows(sd: np.ndarray, normal: np.ndarray, rel_v: np.ndarray, p: Any, min_distance_m: float = 0.05) -> np.ndarray:
    """fsw/apf.py `buffer_force` of N rows (signed distances (N,), normals and relative velocities
    (N, 3)): eq. 11's form off the surface within R_buffer, plus the damping of inward motion."""
    s = np.maximum(sd, min_distance_m)
    inside = sd < p.r_buffer_m
    f = np.where(inside, p.k_r_target * (1.0 / s - 1.0 / p.r_buffer_m) / (s * s), 0.0)[:, None] * normal
    vn = rel_v[:, 0] * normal[:, 0] + rel_v[:, 1] * normal[:, 1] + rel_v[:, 2] * normal[:, 2]
    damp = inside & (vn < 0.0)
    return np.where(damp[:, None], f - (p.buffer_damping_nspm * vn)[:, None] * normal, np.where(inside[:, None], f, 0.0))


FLOORS: dict[str, Callable[..., dict]] = {"p000-capture": floor_capture, "p001-lattice": floor_lattice, "p003-servicer": floor_surround,
                                          "p004-lbdnn": floor_servicing}


def floor(sc: Any, steps: int | None = None) -> dict:
    """The floor of the scenario's mission (by its controller), run once."""
    name = sc.controller_of(sc.ids[-1])[0]
    if name not in FLOORS:
        raise ValueError(f"no mission floor for controller {name!r}; known: {sorted(FLOORS)}")
    return FLOORS[name](sc, steps)


if __name__ == "__main__":
    from vectorised_floor import cli

    cli(floor, ROOT / "deploy/scenarios/servicing-6.toml")
