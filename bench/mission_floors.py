"""The compute floors of papers 001, 003 and 004: each mission in one plain numpy loop (issue 29).

    python bench/mission_floors.py deploy/scenarios/servicing-6.toml [--duration 60] [--repeats 3]

What bench/vectorised_floor.py is for paper 002, for the three mission worlds (`[plant] fidelity =
"cw"` or `"inertial"`): the same scenario (initial states, step, duration, per-craft actuator
limits, controller parameters), the same control law and the same dynamics, written as one loop
over arrays of all spacecraft, without nodes, bus, messages, recorder, link model, contact events
or validation. What it shares with the project is the mathematics only: the plant's propagators'
pure functions (the closed-form HCW matrices of plant/dynamics/cw.py; the DOP853 tableau and step
of plant/dynamics/rk_tableau.py, with the right-hand side written here: two-body, J2 and drag as in
plant/dynamics/absolute_j2.py), and the flight software's pure functions over arrays (the
Tersoff-Brenner forces of paper 001; the funnel law, Nash CT gradient kernel and relative dynamics
of paper 003; the Lb-DNN forward pass and internal-state RK4 of paper 004). The initial conditions
and the per-craft constants are read, before the loop, from the plant's world and the controllers
as the scenario builds them. Everything a step does between those functions (sensing, the link's
one-step delay and float32 payloads, the layer latch, the saturations, the actuator limit, the
frames, the dV) is written here over arrays.

`floor(sc)` dispatches on the scenario's controller; each floor returns the loop's wall time, the
total dV and the final positions in the scenario frame, which must agree with the batch run's truth
(tests/test_mission_floors.py; bench/bench_batch_missions.py --floors reports the difference).
Assumed of the scenario, and checked: no sensing noise for papers 001 and 003 (paper 004's noise is
drawn as its sensing kind draws it), and, where there is a link, every packet delivered at the next
step (no loss, latency or range drop: the scenarios' own links).
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


FLOORS: dict[str, Callable[..., dict]] = {"p001-lattice": floor_lattice, "p003-servicer": floor_surround,
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
