"""Paper 003 flight-software kernels: geometry, threats and their gradients, ξ update, funnel,
packets, sensing, registration."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from agent.controller import Observation, OrbitInfo, make_controller
from agent.missions.p003_surround import nash, packets, sensing
from agent.missions.p003_surround.funnel import funnel_half_width, performance, tt_control
from agent.missions.p003_surround.params import FunnelParams, GameParams, from_dict
from agent.missions.p003_surround.relative_dynamics import natural_rel_accel
from agent.missions.p003_surround.structure import (
    ACSB_SPHERES,
    SLOT_OFFSETS_M,
    SQRT2,
    slots_in_leader_frame,
    sphere_arrays,
)
from agent.missions.p003_surround.threat import (
    pair_threat_grads,
    pair_threats,
    structure_threat,
    structure_threat_grad,
)

RNG = np.random.default_rng(3)
G = GameParams()


def test_table2_restored_is_symmetric() -> None:
    centres, radii = sphere_arrays()
    assert len(ACSB_SPHERES) == 21
    by_part = {}
    for s in ACSB_SPHERES:
        by_part.setdefault(s.part, []).append(s)
    assert all(s.centre_m[0] > 0 for s in by_part["core cabin"][1:])
    assert all(s.centre_m[0] < 0 for s in by_part["transporter"])
    for plus, minus, axis in (("payload cabin I", "payload cabin II", 1), ("solar array I", "solar array II", 2)):
        a = np.array([s.centre_m for s in by_part[plus]])
        b = np.array([s.centre_m for s in by_part[minus]])
        assert np.all(a[:, axis] > 0)
        mirror = b.copy()
        mirror[:, axis] *= -1
        np.testing.assert_array_equal(a, mirror)
        assert [s.radius_m for s in by_part[plus]] == [s.radius_m for s in by_part[minus]]
    assert sorted(set(np.round(radii / SQRT2, 9))) == [5.0, 10.0, 15.0]
    assert np.all(np.abs(centres).max(axis=0) == [80.0, 45.0, 40.0])


def _sweep_clearance(offset_m: np.ndarray) -> float:
    """Min over s in [0, 1.2] and spheres of |o - d_g - s w| - r_g - r_i, w = q_TL(0) - q_TL,d
    (the target's approach, straight since its TT error starts equal on all axes)."""
    centres, radii = sphere_arrays()
    w = np.array([500.0, 500.0, 500.0])
    s = np.linspace(0.0, 1.2, 2401)[:, None, None]
    d = offset_m[None, None, :] - centres[None] - s * w[None, None, :]
    return float((np.linalg.norm(d, axis=2) - radii[None] - G.safe_radius_m).min())


def test_slots_are_not_swept_by_the_target_approach() -> None:
    for offset in SLOT_OFFSETS_M:
        assert _sweep_clearance(offset) > 10.0, offset
    assert _sweep_clearance(np.array([50.0, 50.0, 50.0])) < 0.0  # the corner left out is swept
    np.testing.assert_array_equal(slots_in_leader_frame(np.array([400.0, 0, 0]))[0], [450.0, 50.0, -50.0])


def _fd_grad(fun, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    out = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        xp, xm = x.copy(), x.copy()
        xp[idx] += h
        xm[idx] -= h
        out[idx] = (fun(xp) - fun(xm)) / (2 * h)
    return out


def test_structure_threat_gradient_matches_finite_differences() -> None:
    centres, radii = sphere_arrays()
    p = np.array([22.0, 27.0, 3.0])  # 0.6 m outside the (20, 0, 0) sphere + r_i: barrier is steep
    f = lambda x: float(structure_threat(x, centres, radii, G.safe_radius_m, G.h_cg, G.barrier_floor_m2))  # noqa: E731
    grad = structure_threat_grad(p, centres, radii, G.safe_radius_m, G.h_cg, G.barrier_floor_m2)
    np.testing.assert_allclose(grad, _fd_grad(f, p), rtol=1e-5)
    assert np.dot(grad, p - np.array([20.0, 0, 0])) < 0  # the threat grows towards the sphere


def test_pair_threat_gradients_match_finite_differences() -> None:
    p = np.array([[0.0, 0, 0], [10.5, 1.0, 0.0], [3.0, 12.0, -1.0], [40.0, 40.0, 40.0]])
    r = np.full(4, 5.0)
    grads = pair_threat_grads(p, r, 1.0, 1e-3)
    for k in range(4):
        for i in range(4):
            def f(x: np.ndarray, i: int = i, k: int = k) -> float:
                q = p.copy()
                q[i] = x
                return float(pair_threats(q, r, 1.0, 1e-3)[k])
            expected = _fd_grad(f, p[i].copy())
            got = grads[i].sum(axis=0) if k == i else grads[i, k]
            np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-12)


def _near_threat_state() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    slots = slots_in_leader_frame(np.array([400.0, 0, 0]))
    centres, radii = sphere_arrays()
    centres = centres + np.array([400.0, 0.0, 0.0])
    xi = RNG.normal(0.0, 1.0, (6, 6))
    xi[0, :3] = np.array([420.0, 27.0, 3.0]) - slots[0]  # ξ_1 close to a core-cabin sphere
    xi[1, :3] = slots[0] + xi[0, :3] + np.array([10.3, 1.0, 0.0]) - slots[1]  # ξ_2 close to ξ_1
    x_err = RNG.normal(0.0, 5.0, (6, 6))
    return x_err, xi, slots, centres, radii


def test_xi_rate_is_minus_eta_times_gradient_of_summed_values() -> None:
    x_err, xi, slots, centres, radii = _near_threat_state()
    total = lambda z: float(nash.values(x_err, z, slots, centres, radii, G).sum())  # noqa: E731
    expected = -G.eta * _fd_grad(total, xi, h=1e-5)
    got = nash.xi_rate(x_err, xi, slots, centres, radii, G)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-7)
    assert np.abs(got[0, :3]).max() > 10 * np.abs(got[3, :3]).max()  # the barrier is felt near contact


def test_ct_gradient_is_dV_i_dx_i() -> None:
    x_err, xi, slots, centres, radii = _near_threat_state()
    got = nash.value_grad_x(x_err, xi, slots, centres, radii, G)
    for i in (0, 4):
        def f(row: np.ndarray, i: int = i) -> float:
            x = x_err.copy()
            x[i] = row
            return float(nash.values(x, xi, slots, centres, radii, G)[i])
        np.testing.assert_allclose(got[i], _fd_grad(f, x_err[i].copy()), rtol=1e-6)


def test_slow_mode_of_the_literal_weights() -> None:
    rate = nash.slow_mode_rate(G)
    assert rate == pytest.approx(nash.slow_mode_rate_approx(G), rel=0.02)
    assert rate < G.eta * (G.kappa + G.gamma)
    assert 1.0 / rate > 300.0  # the §5 weights cannot settle within the 300 s run


def test_funnel_numbers() -> None:
    p = FunnelParams()
    assert funnel_half_width(0.0, p.mu1, p.a1_per_s) == np.inf
    assert performance(1e9, p.mu1, p.a1_per_s) == pytest.approx(p.mu1)
    assert funnel_half_width(300.0, p.mu1, p.a1_per_s) == pytest.approx(47.50, abs=0.01)  # not ±1 m


def test_funnel_holds_a_large_initial_error_on_a_disturbed_double_integrator() -> None:
    """q'' = u_L/m_L + d(t), |d| bounded and unknown to the controller, unsaturated (the theorem's
    setting); initial error 10 km and 40 m/s away: |q~_l| < tan(k1 π/2) at every step, and the
    error at 300 s is the steady bias of a constant disturbance, at most d m_L k1 k2/(λ1 λ2)."""
    p = FunnelParams()
    q_des = np.asarray(p.q_des_m)
    q = q_des + np.array([1.0e4, -3.0e3, 50.0])
    v = np.array([40.0, -40.0, 0.0])
    dt = 0.002  # the control is singular at the bound: at 5 ms the sampled loop leaves it
    worst = 0.0
    for k in range(int(300.0 / dt)):
        t = k * dt
        d = np.array([0.02, -0.01 * np.sin(0.05 * t), 0.015 * np.cos(0.1 * t)])
        u, _, _ = tt_control(q, v, t, p)
        a = u / p.mass_kg + d
        v = v + a * dt
        q = q + v * dt
        bound = funnel_half_width(t + dt, p.mu1, p.a1_per_s)
        worst = max(worst, float(np.abs(q - q_des).max() / bound))
    assert worst < 1.0
    k12 = performance(300.0, p.mu1, p.a1_per_s) * performance(300.0, p.mu2, p.a2_per_s)
    bias_bound = 0.02 * p.mass_kg * k12 / (p.lambda1 * p.lambda2)  # 11.5 m for d_x = 0.02 m/s^2
    assert 0.5 * bias_bound < abs(q[0] - q_des[0]) < bias_bound
    assert np.abs(q[1:] - q_des[1:]).max() < 2.0


def test_natural_rel_accel_reduces_to_hcw() -> None:
    a_m, n = 6878137.0, 1.1e-3
    q, v = np.array([10.0, 5.0, 3.0]), np.array([0.1, 0.2, 0.3])
    hcw = np.array([3 * n**2 * q[0] + 2 * n * v[1], -2 * n * v[0], -n**2 * q[2]])
    np.testing.assert_allclose(natural_rel_accel(q, v, a_m, n), hcw, atol=1e-10)


def test_packets_round_trip() -> None:
    tt = packets.TTPacket(1234, np.array([0.1, -2.0, 3.0]), np.array([900.0, 500.0, -500.0]), np.array([5.0, 5, -5]))
    raw = packets.encode_tt(tt)
    assert len(raw) == 41
    back = packets.decode_tt(raw)
    assert back.step == 1234
    np.testing.assert_allclose(back.q_tl_m, tt.q_tl_m, rtol=1e-7)
    np.testing.assert_allclose(back.leader_accel_mps2, tt.leader_accel_mps2, rtol=1e-7)
    ct = packets.CTPacket(5, np.arange(6.0), -np.arange(6.0))
    raw = packets.encode_ct(ct)
    assert len(raw) == 50
    back = packets.decode_ct(raw)
    assert back.index == 5
    np.testing.assert_array_equal(back.xi, ct.xi)
    with pytest.raises(ValueError, match="41 bytes"):
        packets.decode_tt(raw)
    with pytest.raises(ValueError, match="version"):
        packets.decode_ct(b"\x02" + raw[1:])


def test_sensing_dicts() -> None:
    s = sensing.RelativeState(np.array([1.0, 2, 3]), np.array([0.1, 0.2, 0.3]))
    back = sensing.read({sensing.LEADER_REL_KEY: s.to_dict()}, sensing.LEADER_REL_KEY)
    np.testing.assert_array_equal(back.position_m, s.position_m)
    with pytest.raises(KeyError, match="p003.target_rel"):
        sensing.read({}, sensing.TARGET_REL_KEY)
    with pytest.raises(ValueError, match="position_m"):
        sensing.RelativeState(np.array([1.0, np.nan, 0]), np.zeros(3))


def test_params_reject_unknown_keys() -> None:
    with pytest.raises(ValueError, match="kapa"):
        from_dict(GameParams, {"kapa": 1.0})
    with pytest.raises(ValueError, match="saturate"):
        replace(G, saturate="both")


def test_registered_controllers_step() -> None:
    orbit = OrbitInfo(6878137.0, 1.1e-3)
    leader = make_controller("p003-leader", "lsat", orbit, {})
    obs = Observation(0, 0.0, 0.0, [], np.zeros((0, 3)), np.zeros((0, 3)),
                      extra={sensing.TARGET_REL_KEY: {"position_m": [900, 500, 500], "velocity_mps": [5, 5, 5]}})
    cmd = leader.step(obs)
    assert np.linalg.norm(cmd.accel_mps2) * 60.0 <= 180.0 + 1e-9
    assert cmd.transmissions[0].type == packets.TT_TYPE
    sat = make_controller("p003-servicer", "ssat3", orbit, {})
    assert sat.index == 2
    obs = Observation(1, 0.1, 0.0, [], np.zeros((0, 3)), np.zeros((0, 3)),
                      extra={sensing.LEADER_REL_KEY: {"position_m": [210, 30, 100], "velocity_mps": [1, 3, 2]}},
                      isl_rx=[type("P", (), {"src": "lsat", "type": t.type, "payload": t.payload, "sent_t": 0.0})()
                              for t in cmd.transmissions])
    c = sat.step(obs)
    assert np.linalg.norm(c.accel_mps2) * 50.0 <= 20.0 + 1e-9
    assert sat.telemetry.saturated
    assert packets.decode_ct(c.transmissions[0].payload).index == 2
