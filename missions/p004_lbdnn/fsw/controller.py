"""Servicer i's flight software for paper 004: rho-filter, observer, Lb-DNN controller, adaptation.

Discrete-time implementation of the continuous laws (eqs. 25-28), one call per measurement:

1. at step k (time t_k) the internal state x = (eta_hat, zeta_hat, nu, theta_hat) is propagated
   from t_{k-1} to t_k with RK4 (`rk4_substeps` steps), holding what was true over that interval:
   the measurement eta_{k-1}, the servicer's own u_i(k-1), and the neighbours' u_j(k-1) and
   theta_hat_j(t_{k-1}) received over the link (sent at step k-1); theta_hat is then clipped to
   the projection's ball;
2. eta_k is formed from the new measurements (eq. 12), rho_k from nu and eta_tilde (eq. 25),
   and u_i(k) by eq. 27; u_i(k) and theta_hat_i(t_k) are broadcast (packet.py).

The observer starts at eta_hat = zeta_hat = 0 (eq. 26) and nu = (k3 + k4) eta_0 (rho(0) = 0).
Frame: inertial axes for measurements and command (sensing.py). With `max_accel_mps2` set (a
stated variant; the paper has no limit) u_i is clipped per axis before it is used or broadcast,
so the observers integrate the acceleration that was applied.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from agent.controller import Command, Observation, OrbitInfo, Transmission, register
from missions.p004_lbdnn.fsw import adaptation, lbdnn, observer, packet, rho_filter
from missions.p004_lbdnn.fsw.control_law import control
from missions.p004_lbdnn.fsw.sensing import DefunctMeasurement, neighbour_positions
from missions.p004_lbdnn.contract import CONTROLLER, ServicerConfig, mission_from_params


@dataclass(frozen=True)
class InternalState:
    """A snapshot of the servicer's estimates at the last step, for telemetry and tests."""

    t_s: float
    eta: np.ndarray  # measured eta_i (eq. 12)
    eta_hat: np.ndarray
    zeta_hat: np.ndarray
    rho: np.ndarray
    theta_hat: np.ndarray
    phi: np.ndarray  # Phi_i(kappa_i, theta_hat_i)
    accel_mps2: np.ndarray  # u_i


class LbdnnServicer:
    """One servicer (paper 004 §4.2), behind the Controller protocol."""

    name = CONTROLLER

    def __init__(self, cfg: ServicerConfig, weight_bytes: int = 4) -> None:
        self.cfg = cfg
        self.g = cfg.gains
        self.weight_bytes = weight_bytes
        p = lbdnn.n_params()
        self.theta = (lbdnn.kaiming_init(np.random.default_rng(cfg.weight_seed))
                      if cfg.use_network else np.zeros(p))
        self.eta_hat = np.zeros(3)
        self.zeta_hat = np.zeros(3)
        self.nu = np.zeros(3)
        self._t_prev: float | None = None
        self._eta_prev = np.zeros(3)
        self._u_prev = np.zeros(3)
        self._d_last: dict[str, np.ndarray] = {}
        self._y_last: np.ndarray | None = None
        self._u_nb: dict[str, np.ndarray] = {j: np.zeros(3) for j in cfg.neighbours}
        self._theta_nb: dict[str, np.ndarray] = {}
        self._rx_step: dict[str, int] = {}
        self.stale_measurements = 0  # neighbour / y_i measurements held from an earlier step
        self.rejected_packets = 0
        self.state: InternalState | None = None

    # -- measurements and link -------------------------------------------------------------
    def _measured_eta(self, obs: Observation) -> np.ndarray:
        rows = {nid: np.asarray(obs.rel_position_m[k], dtype=float)
                for k, nid in enumerate(obs.neighbour_ids)}
        rows.update(neighbour_positions(obs.extra))  # the stack's sensing kind: named arrays
        for j in self.cfg.neighbours:
            if j in rows:
                self._d_last[j] = rows[j]
            elif j in self._d_last:
                self.stale_measurements += 1
            else:
                raise ValueError(f"{self.cfg.sc_id}: no relative position to graph neighbour {j!r} "
                                 f"at step {obs.step} (got {list(obs.neighbour_ids)})")
        y = None
        if self.cfg.b:
            m = DefunctMeasurement.from_extra(obs.extra, self.cfg.c_matrix.shape[0])
            if m is not None:
                self._y_last = m.y_m
            elif self._y_last is not None:
                self.stale_measurements += 1
            y = self._y_last
        d = np.array([self._d_last[j] for j in self.cfg.neighbours]).reshape(-1, 3)
        return observer.relative_position_error(d, y, self.cfg.c_matrix, self.cfg.b)

    def _read_link(self, obs: Observation) -> None:
        for msg in obs.isl_rx:
            if msg.type != packet.PACKET_TYPE or msg.src not in self._u_nb:
                continue
            try:
                pkt = packet.decode(bytes(msg.payload))
            except ValueError:
                self.rejected_packets += 1
                continue
            if pkt.step < self._rx_step.get(msg.src, -1) or pkt.theta.size != lbdnn.n_params():
                continue
            self._rx_step[msg.src] = pkt.step
            self._u_nb[msg.src] = pkt.accel_mps2
            self._theta_nb[msg.src] = pkt.theta

    # -- dynamics of the internal state ------------------------------------------------------
    def _derivative(self, x: np.ndarray, eta: np.ndarray, coupling: np.ndarray,
                    theta_nb: np.ndarray) -> np.ndarray:
        """d/dt (eta_hat, zeta_hat, nu, theta_hat) over one hold interval (eqs. 25, 26, 28)."""
        eta_hat, zeta_hat, nu, theta = x[0:3], x[3:6], x[6:9], x[9:]
        eta_tilde = eta - eta_hat
        rho_i = rho_filter.rho(eta_tilde, nu, self.g)
        dx = np.empty_like(x)
        dx[0:3] = zeta_hat
        dx[3:6] = observer.zeta_hat_dot(coupling, eta_tilde, rho_i, self.g)
        dx[6:9] = rho_filter.nu_dot(eta_tilde, rho_i, self.g)
        if self.cfg.use_network:
            kappa = np.concatenate([eta, zeta_hat])
            fwd = lbdnn.forward(kappa, theta)
            jac = lbdnn.jacobian(fwd)
            direction = adaptation.adaptation_direction(jac, zeta_hat, eta, theta, theta_nb, self.g)
            dx[9:] = adaptation.projection(direction, theta, self.cfg.theta_bar, self.cfg.proj_epsilon)
        else:
            dx[9:] = 0.0
        return dx

    def _propagate(self, dt: float) -> None:
        eta = self._eta_prev
        u_nb = np.array([self._u_nb[j] for j in self.cfg.neighbours]).reshape(-1, 3)
        coupling = observer.input_coupling(self._u_prev, u_nb, self.cfg.ctc)
        theta_nb = np.array([self._theta_nb.get(j, self.theta) for j in self.cfg.neighbours])
        x = np.concatenate([self.eta_hat, self.zeta_hat, self.nu, self.theta])
        h = dt / self.cfg.rk4_substeps
        for _ in range(self.cfg.rk4_substeps):
            k1 = self._derivative(x, eta, coupling, theta_nb)
            k2 = self._derivative(x + 0.5 * h * k1, eta, coupling, theta_nb)
            k3 = self._derivative(x + 0.5 * h * k2, eta, coupling, theta_nb)
            k4 = self._derivative(x + h * k3, eta, coupling, theta_nb)
            x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            x[9:] = adaptation.clip_to_ball(x[9:], self.cfg.theta_bar + self.cfg.proj_epsilon)
        self.eta_hat, self.zeta_hat, self.nu, self.theta = x[0:3], x[3:6], x[6:9], x[9:]

    # -- the step ---------------------------------------------------------------------------
    def step(self, obs: Observation) -> Command:
        eta = self._measured_eta(obs)
        self._read_link(obs)
        if self._t_prev is None:
            self.nu = rho_filter.nu_initial(eta - self.eta_hat, self.g)
        else:
            dt = float(obs.t_s) - self._t_prev
            if not dt > 0.0:
                raise ValueError(f"{self.cfg.sc_id}: time went from {self._t_prev} to {obs.t_s}")
            self._propagate(dt)
        eta_tilde = eta - self.eta_hat
        rho_i = rho_filter.rho(eta_tilde, self.nu, self.g)
        phi = (lbdnn.evaluate(np.concatenate([eta, self.zeta_hat]), self.theta)
               if self.cfg.use_network else np.zeros(3))
        u = control(phi, eta, self.zeta_hat, eta_tilde, rho_i, self.g)
        if self.cfg.max_accel_mps2 is not None:
            # the thrust-limited variant: the applied (clipped) u is what the observers must see
            u = np.clip(u, -self.cfg.max_accel_mps2, self.cfg.max_accel_mps2)
        self._t_prev, self._eta_prev, self._u_prev = float(obs.t_s), eta, u
        self.state = InternalState(float(obs.t_s), eta, self.eta_hat.copy(), self.zeta_hat.copy(),
                                   rho_i, self.theta.copy(), phi, u)
        payload = packet.encode(packet.StatePacket(obs.step, float(obs.t_s), u, self.theta),
                                self.weight_bytes)
        return Command(accel_mps2=u, mode="lbdnn",
                       transmissions=[Transmission(type=packet.PACKET_TYPE, payload=payload)])


@register(CONTROLLER)
def make_servicer(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> LbdnnServicer:
    """Scenario factory: the `[controller]` table describes the whole network (the room's contract,
    missions/p004_lbdnn/contract.py `mission_from_params`)."""
    params = dict(params)
    weight_bytes = int(params.pop("weight_bytes", 4))
    return LbdnnServicer(mission_from_params(params).servicer(sc_id), weight_bytes=weight_bytes)
