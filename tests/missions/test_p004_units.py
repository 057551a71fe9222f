"""Paper 004's room, piece by piece: the Lb-DNN and its Jacobian, the rho-filter, the observer,
the projection, the link packet, the configuration and the sensing keys."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.missions.p004_lbdnn.fsw import adaptation, lbdnn, observer, packet, rho_filter
from swarmhil.missions.p004_lbdnn.fsw.sensing import DefunctMeasurement
from swarmhil.missions.p004_lbdnn.contract import KEY_Y, Gains, MissionConfig, mission_from_params

ORBIT = OrbitInfo(semi_major_axis_m=6878137.0, mean_motion_radps=1.1e-3)


def test_parameter_count_is_the_papers_103() -> None:
    assert lbdnn.n_params() == 103
    assert (6 + 1) * 4 + 3 * (4 + 1) * 4 + (4 + 1) * 3 == 103
    theta = lbdnn.kaiming_init(np.random.default_rng(0))
    assert theta.shape == (103,)
    mats = lbdnn.unpack(theta)
    assert [m.shape for m in mats] == [(7, 4), (5, 4), (5, 4), (5, 4), (5, 3)]
    assert np.array_equal(lbdnn.pack(mats), theta)


def test_forward_matches_a_hand_written_network() -> None:
    """Eq. 2 with column-major vec(): an independent loop over explicit matrices."""
    rng = np.random.default_rng(1)
    theta = rng.normal(size=103)
    kappa = rng.normal(size=6)
    mats, at = [], 0
    for a, b in [(6, 4), (4, 4), (4, 4), (4, 4), (4, 3)]:
        v = np.zeros((a + 1, b))
        for col in range(b):  # vec() stacks columns
            v[:, col] = theta[at:at + a + 1]
            at += a + 1
        mats.append(v)
    x = np.r_[kappa, 1.0]
    for v in mats[:-1]:
        z = v.T @ x
        x = np.r_[z / (1.0 + np.exp(-z)), 1.0]
    expected = np.tanh(mats[-1].T @ x)
    np.testing.assert_allclose(lbdnn.evaluate(kappa, theta), expected, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("scale", [0.3, 1.0, 1.5])
def test_jacobian_matches_central_differences(scale: float) -> None:
    """Eq. 3 (times the tanh output factor) against central differences, every one of 103 columns."""
    rng = np.random.default_rng(int(10 * scale))
    theta = scale * rng.normal(size=103) / 2.0
    kappa = scale * rng.normal(size=6)
    jac = lbdnn.jacobian(lbdnn.forward(kappa, theta))
    h = 1e-6
    fd = np.empty((3, 103))
    for i in range(103):
        d = np.zeros(103)
        d[i] = h
        fd[:, i] = (lbdnn.evaluate(kappa, theta + d) - lbdnn.evaluate(kappa, theta - d)) / (2 * h)
    assert np.max(np.abs(jac - fd)) < 1e-8
    assert np.max(np.abs(fd)) > 1e-2  # a real test: the network is not saturated here


def test_jacobian_with_kaiming_weights_and_large_inputs() -> None:
    """Kaiming weights (§6) and inputs of several units: a partly saturated network, still exact."""
    theta = lbdnn.kaiming_init(np.random.default_rng(4))
    kappa = np.array([3000.0, -1500.0, 800.0, 0.2, -0.1, 0.05]) / 1000.0 * 1.7
    jac = lbdnn.jacobian(lbdnn.forward(kappa, theta))
    h = 1e-6
    fd = np.array([(lbdnn.evaluate(kappa, theta + h * np.eye(103)[i])
                    - lbdnn.evaluate(kappa, theta - h * np.eye(103)[i])) / (2 * h) for i in range(103)]).T
    assert np.max(np.abs(jac - fd)) < 1e-7 * max(1.0, np.max(np.abs(fd)))


def test_swish_is_stable_for_kilometre_inputs() -> None:
    x = np.array([-5e4, -40.0, 0.0, 40.0, 5e4])
    assert np.all(np.isfinite(lbdnn.swish(x))) and np.all(np.isfinite(lbdnn.swish_prime(x)))
    assert lbdnn.swish(np.array([5e4]))[0] == pytest.approx(5e4)


def test_rho_filter_integral_form_obeys_eq_34() -> None:
    """d rho / dt from the integral form equals eta_tilde - (k3+k4) r_tilde - k5 rho (eq. 34),
    with r_tilde = eta_tilde_dot + k3 eta_tilde + rho (eq. 24), for any smooth eta_tilde(t)."""
    g = Gains(k3=0.7, k4=0.4, k5=0.9)
    eta_t = lambda t: np.array([np.sin(t), np.cos(2 * t), t**2])  # noqa: E731
    eta_t_dot = lambda t: np.array([np.cos(t), -2 * np.sin(2 * t), 2 * t])  # noqa: E731
    nu = rho_filter.nu_initial(eta_t(0.0), g)
    assert np.allclose(rho_filter.rho(eta_t(0.0), nu, g), 0.0)
    dt, t = 1e-4, 0.0
    for _ in range(5000):  # RK2 on nu
        r0 = rho_filter.rho(eta_t(t), nu, g)
        k1 = rho_filter.nu_dot(eta_t(t), r0, g)
        nu_mid = nu + 0.5 * dt * k1
        k2 = rho_filter.nu_dot(eta_t(t + dt / 2), rho_filter.rho(eta_t(t + dt / 2), nu_mid, g), g)
        nu, t = nu + dt * k2, t + dt
    rho_t = rho_filter.rho(eta_t(t), nu, g)
    rho_dot = -(g.k3 + g.k4) * eta_t_dot(t) + rho_filter.nu_dot(eta_t(t), rho_t, g)
    r_tilde = eta_t_dot(t) + g.k3 * eta_t(t) + rho_t
    np.testing.assert_allclose(rho_dot, eta_t(t) - (g.k3 + g.k4) * r_tilde - g.k5 * rho_t, atol=1e-12)


def test_observer_converges_on_a_linear_six_agent_network() -> None:
    """Double integrators e_i'' = -u_i with a known, persistently exciting input: with the true
    u_j shared, eta_hat -> eta and zeta_hat -> eta_dot (eqs. 25, 26) on the paper's graph."""
    mission = MissionConfig()
    g, h = mission.gains, mission.interaction_matrix()
    n, dt = 6, 2e-3
    rng = np.random.default_rng(3)
    e, e_dot = rng.normal(0, 50, (n, 3)), rng.normal(0, 2, (n, 3))
    cfgs = [mission.servicer(s) for s in mission.servicers]
    idx = {s: i for i, s in enumerate(mission.servicers)}
    eta = (h @ e.ravel()).reshape(n, 3)
    eta_hat, zeta_hat = np.zeros((n, 3)), np.zeros((n, 3))
    nu = np.array([rho_filter.nu_initial(eta[i], g) for i in range(n)])
    for step in range(int(25.0 / dt)):
        t = step * dt
        u = np.array([[np.sin(0.3 * t + i), np.cos(0.2 * t * (i + 1)), 0.1 * i] for i in range(n)])
        eta = (h @ e.ravel()).reshape(n, 3)
        for i, c in enumerate(cfgs):
            eta_tilde = eta[i] - eta_hat[i]
            rho_i = rho_filter.rho(eta_tilde, nu[i], g)
            coupling = observer.input_coupling(u[i], u[[idx[j] for j in c.neighbours]], c.ctc)
            zd = observer.zeta_hat_dot(coupling, eta_tilde, rho_i, g)
            nu[i] = nu[i] + dt * rho_filter.nu_dot(eta_tilde, rho_i, g)
            eta_hat[i] = eta_hat[i] + dt * zeta_hat[i]
            zeta_hat[i] = zeta_hat[i] + dt * zd
        e, e_dot = e + dt * e_dot, e_dot - dt * u
    eta = (h @ e.ravel()).reshape(n, 3)
    eta_dot = (h @ e_dot.ravel()).reshape(n, 3)
    # error dynamics decay like exp(-0.65 t): 25 s leaves ~1e-7 of the initial errors (~1 km)
    assert np.max(np.abs(eta - eta_hat)) < 1e-3
    assert np.max(np.abs(eta_dot - zeta_hat)) < 1e-3


def test_relative_position_error_is_h_times_e() -> None:
    """eq. 12 from measurements equals (H e)_i of eq. 30."""
    mission = mission_from_params({"b": {"s2": 0, "s5": 0}})
    rng = np.random.default_rng(5)
    q0, q = rng.normal(size=3), rng.normal(size=(6, 3))
    e = q0 - q
    eta_ens = (mission.interaction_matrix() @ e.ravel()).reshape(6, 3)
    for i, s in enumerate(mission.servicers):
        c = mission.servicer(s)
        d = np.array([q[mission.servicers.index(j)] - q[i] for j in c.neighbours])
        eta = observer.relative_position_error(d, c.c_matrix @ e[i], c.c_matrix, c.b)
        np.testing.assert_allclose(eta, eta_ens[i], atol=1e-12)


def test_adaptation_direction_and_projection() -> None:
    g = Gains()
    rng = np.random.default_rng(7)
    theta = rng.normal(size=103)
    jac = rng.normal(size=(3, 103))
    zeta, eta = rng.normal(size=3), rng.normal(size=3)
    nbs = rng.normal(size=(2, 103))
    d = adaptation.adaptation_direction(jac, zeta, eta, theta, nbs, g)
    consensus = theta - ((nbs[0] - theta) + (nbs[1] - theta))  # as printed in eq. 28
    expected = g.gamma * (jac.T @ (zeta + g.k1 * eta) - g.k6 * consensus)
    np.testing.assert_allclose(d, expected, atol=1e-14)
    bar, eps = 5.0, 1.0
    inside = theta / np.linalg.norm(theta) * 4.0
    assert np.array_equal(adaptation.projection(d, inside, bar, eps), d)
    outer = theta / np.linalg.norm(theta) * (bar + eps)
    radial_out = outer / np.linalg.norm(outer)
    pushed = adaptation.projection(radial_out + 0.3 * d, outer, bar, eps)
    assert float(pushed @ outer) == pytest.approx(0.0, abs=1e-12)  # no outward part at the edge
    assert np.array_equal(adaptation.projection(-radial_out, outer, bar, eps), -radial_out)
    assert np.linalg.norm(adaptation.clip_to_ball(10.0 * outer, bar + eps)) == pytest.approx(bar + eps)


@pytest.mark.parametrize("weight_bytes, size", [(4, 454), (8, 866)])
def test_packet_round_trip(weight_bytes: int, size: int) -> None:
    rng = np.random.default_rng(2)
    pkt = packet.StatePacket(step=1234, t_s=123.4, accel_mps2=rng.normal(size=3), theta=rng.normal(size=103))
    raw = packet.encode(pkt, weight_bytes)
    assert len(raw) == size
    back = packet.decode(raw)
    assert back.step == 1234 and back.t_s == 123.4
    np.testing.assert_array_equal(back.accel_mps2, pkt.accel_mps2)
    tol = 1e-6 if weight_bytes == 4 else 0.0
    np.testing.assert_allclose(back.theta, pkt.theta, rtol=tol, atol=tol)
    with pytest.raises(ValueError, match="bytes"):
        packet.decode(raw[:-1])
    with pytest.raises(ValueError, match="magic"):
        packet.decode(b"XX" + raw[2:])


def test_sensing_keys_round_trip() -> None:
    m = DefunctMeasurement(y_m=np.array([1.0, -2.0]))
    extra = m.to_extra()
    back = DefunctMeasurement.from_extra(extra, 2)
    assert back is not None and np.array_equal(back.y_m, m.y_m)
    assert DefunctMeasurement.from_extra({}, 2) is None
    assert DefunctMeasurement.from_extra({**extra, "p004.y_valid": False}, 2) is None
    with pytest.raises(ValueError, match="rows"):
        DefunctMeasurement.from_extra({KEY_Y: [1.0, 2.0, 3.0]}, 2)


def test_stack_measurements_read_as_the_loops() -> None:
    """The plant's sensing kind (missions/p004_lbdnn/sense.py) sends named arrays p004.d_m/<j> and
    p004.y_m/<defunct>; the controller reads them exactly as rel_position_m rows and p004.y_m."""
    from swarmhil.missions.p004_lbdnn.fsw.sensing import neighbour_positions

    d = np.array([[100.0, 0.0, 0.0], [0.0, 50.0, 0.0]])
    y = np.array([10.0])
    named = {"p004.d_m/s2": d[0], "p004.d_m/s6": d[1], "p004.y_m/defunct": y}
    assert set(neighbour_positions(named)) == {"s2", "s6"}
    assert np.array_equal(DefunctMeasurement.from_extra(named, 1).y_m, y)
    with pytest.raises(ValueError, match="more than one"):
        DefunctMeasurement.from_extra({**named, "p004.y_m/other": y}, 1)
    with pytest.raises(ValueError, match="3 finite"):
        neighbour_positions({"p004.d_m/s2": [1.0, 2.0]})
    a, b = (make_controller("p004-lbdnn", "s1", ORBIT, {}) for _ in range(2))
    for k in range(3):
        obs_loop = Observation(step=k, t_s=0.1 * k, u_rad=0.0, neighbour_ids=["s2", "s6"], rel_position_m=d * (1 + k),
                               rel_velocity_mps=np.zeros_like(d), extra=DefunctMeasurement(y_m=y).to_extra())
        obs_stack = Observation(step=k, t_s=0.1 * k, u_rad=0.0, neighbour_ids=[], rel_position_m=np.zeros((0, 3)),
                                rel_velocity_mps=np.zeros((0, 3)),
                                extra={"p004.d_m/s2": d[0] * (1 + k), "p004.d_m/s6": d[1] * (1 + k),
                                       "p004.y_m/defunct": y})
        assert np.array_equal(a.step(obs_loop).accel_mps2, b.step(obs_stack).accel_mps2)
    assert a.stale_measurements == b.stale_measurements == 0


def test_scenario_graph_is_trackable_and_h_positive_definite() -> None:
    """Definition 1 and Lemma 1 on the chosen ring with b_i = 1; the paper's sufficient
    lambda_min(H) > 1 is not met by any graph with these C_i (even complete: 0.82)."""
    mission = MissionConfig()
    assert mission.trackable()
    lam = mission.lambda_min_h()
    assert lam == pytest.approx(0.391, abs=1e-3)
    assert np.allclose(mission.interaction_matrix(), mission.interaction_matrix().T)
    path = mission_from_params({"graph": "path"})
    assert path.lambda_min_h() == pytest.approx(0.376, abs=1e-3)
    only_1_6 = mission_from_params({"b": {"s2": 0, "s3": 0, "s4": 0, "s5": 0}})
    assert not only_1_6.trackable()  # two rank-one sensors: rank 2
    assert only_1_6.lambda_min_h() < 1e-9
    with pytest.raises(ValueError, match="unknown p004-lbdnn"):
        mission_from_params({"k1": 0.5})


def test_controller_registered_and_speaks_over_the_link() -> None:
    """A step from the registry: the first command is k2 (k1 - k3) eta + Phi = Phi (k1 = k3),
    and the packet carries u_i and theta_hat_i."""
    ctrl = make_controller("p004-lbdnn", "s1", ORBIT, {})
    cfg = ctrl.cfg
    assert cfg.neighbours == ("s2", "s6")
    d = np.array([[100.0, 0.0, 0.0], [0.0, 50.0, 0.0]])
    extra = DefunctMeasurement(y_m=np.array([10.0])).to_extra()
    obs = Observation(step=0, t_s=0.0, u_rad=0.0, neighbour_ids=["s2", "s6"], rel_position_m=d,
                      rel_velocity_mps=np.zeros_like(d), extra=extra)
    cmd = ctrl.step(obs)
    eta = d.sum(axis=0) + cfg.c_matrix.T @ np.array([10.0])
    np.testing.assert_allclose(ctrl.state.eta, eta)
    np.testing.assert_allclose(cmd.accel_mps2, ctrl.state.phi, atol=1e-12)
    (tx,) = cmd.transmissions
    pkt = packet.decode(tx.payload)
    np.testing.assert_allclose(pkt.accel_mps2, cmd.accel_mps2)
    np.testing.assert_allclose(pkt.theta, ctrl.state.theta_hat, rtol=1e-6)
    # next step: a neighbour's packet is used, a foreign or corrupt one ignored
    rx = [SimpleNamespace(src="s2", type=packet.PACKET_TYPE, payload=packet.encode(
              packet.StatePacket(0, 0.0, np.ones(3), np.zeros(103))), sent_t=0.0),
          SimpleNamespace(src="s6", type=packet.PACKET_TYPE, payload=b"garbage", sent_t=0.0),
          SimpleNamespace(src="s4", type=packet.PACKET_TYPE, payload=tx.payload, sent_t=0.0)]
    obs2 = Observation(step=1, t_s=0.1, u_rad=0.0, neighbour_ids=["s2", "s6"], rel_position_m=d,
                       rel_velocity_mps=np.zeros_like(d), extra=extra, isl_rx=rx)
    ctrl.step(obs2)
    assert ctrl.rejected_packets == 1
    np.testing.assert_array_equal(ctrl._u_nb["s2"], np.ones(3))
    assert "s4" not in ctrl._u_nb


def test_ablation_without_network_commands_pure_feedback() -> None:
    ctrl = make_controller("p004-lbdnn", "s3", ORBIT, {"use_network": False})
    d = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    obs = Observation(step=0, t_s=0.0, u_rad=0.0, neighbour_ids=list(ctrl.cfg.neighbours),
                      rel_position_m=d, rel_velocity_mps=np.zeros_like(d),
                      extra=DefunctMeasurement(y_m=np.zeros(2)).to_extra())
    cmd = ctrl.step(obs)
    np.testing.assert_array_equal(cmd.accel_mps2, np.zeros(3))  # k1 = k3 and rho(0) = 0
    assert np.array_equal(ctrl.state.theta_hat, np.zeros(103))
