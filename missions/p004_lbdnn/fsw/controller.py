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

from swarmhil.agent.controller import (Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, Transmission, decode_once,
                                        register)
from swarmhil.missions.p004_lbdnn.fsw import lbdnn, observer, packet, rho_filter, vectorised
from swarmhil.missions.p004_lbdnn.fsw.control_law import control
from swarmhil.missions.p004_lbdnn.fsw.sensing import DefunctMeasurement, neighbour_positions
from swarmhil.missions.p004_lbdnn.contract import CONTROLLER, Gains, ServicerConfig, mission_from_params


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
        self._law: tuple[ServicerConfig, vectorised.Law] | None = None  # (the config it is of, law())

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

    def _read_link(self, obs: Observation, decoded: dict[tuple[str, bytes], Any] | None = None) -> None:
        """The graph neighbours' u_j and theta_j from the packets received; `decoded`: the payloads
        already decoded this step (agent/controller.py `decode_once`: the packets are read-only)."""
        for msg in obs.isl_rx:
            if msg.type != packet.PACKET_TYPE or msg.src not in self._u_nb:
                continue
            try:
                pkt = decode_once(decoded, msg, _decode)
            except ValueError:
                self.rejected_packets += 1
                continue
            if pkt.step < self._rx_step.get(msg.src, -1) or pkt.theta.size != lbdnn.n_params():
                continue
            self._rx_step[msg.src] = pkt.step
            self._u_nb[msg.src] = pkt.accel_mps2
            self._theta_nb[msg.src] = pkt.theta

    # -- the step ---------------------------------------------------------------------------
    def step(self, obs: Observation) -> Command:
        """Eqs. 25-28 for this servicer: the batch path with N = 1 (`step_batch`), so that an agent
        process and a batch run give the same command, bit for bit."""
        return self.step_batch([self], ObservationBatch.of([self.cfg.sc_id], [obs])).command(0)

    def law(self) -> vectorised.Law:
        """What this servicer's internal-state RK4 shares with others stepped in one call (from its
        frozen config: made once)."""
        if self._law is None or self._law[0] is not self.cfg:
            self._law = (self.cfg, vectorised.Law(self.g, self.cfg.use_network, self.cfg.theta_bar, self.cfg.proj_epsilon,
                                                  self.cfg.rk4_substeps))
        return self._law[1]

    def _begin(self, obs: Observation, decoded: dict[tuple[str, bytes], Any] | None = None) -> tuple[np.ndarray, float | None]:
        """Measure eta_k (eq. 12) and read the link; the hold interval since the last step (None: the first)."""
        eta = self._measured_eta(obs)
        self._read_link(obs, decoded)
        if self._t_prev is None:
            self.nu = rho_filter.nu_initial(eta - self.eta_hat, self.g)
            return eta, None
        dt = float(obs.t_s) - self._t_prev
        if not dt > 0.0:
            raise ValueError(f"{self.cfg.sc_id}: time went from {self._t_prev} to {obs.t_s}")
        return eta, dt

    def _held(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What stays true over the hold interval: x, the input coupling of eq. 26, the neighbours' theta."""
        u_nb = np.array([self._u_nb[j] for j in self.cfg.neighbours]).reshape(-1, 3)
        coupling = observer.input_coupling(self._u_prev, u_nb, self.cfg.ctc)
        theta_nb = np.array([self._theta_nb.get(j, self.theta) for j in self.cfg.neighbours]).reshape(-1, self.theta.size)
        return np.concatenate([self.eta_hat, self.zeta_hat, self.nu, self.theta]), coupling, theta_nb

    @staticmethod
    def _propagate_all(group: list["LbdnnServicer"], dt: float) -> None:
        """RK4 of the internal states of servicers that share their law and hold interval, at once."""
        held = [s._held() for s in group]
        m = max(len(h[2]) for h in held)
        theta_nb = np.zeros((len(group), m, lbdnn.n_params()))
        for r, h in enumerate(held):
            theta_nb[r, :len(h[2])] = h[2]
        x = vectorised.propagate(np.array([h[0] for h in held]), dt, np.array([s._eta_prev for s in group]),
                                 np.array([h[1] for h in held]), theta_nb,
                                 np.array([len(h[2]) for h in held]), group[0].law())
        for r, s in enumerate(group):
            s.eta_hat, s.zeta_hat, s.nu, s.theta = x[r, 0:3], x[r, 3:6], x[r, 6:9], x[r, 9:]

    @classmethod
    def step_batch(cls, controllers: list["LbdnnServicer"], batch: ObservationBatch) -> CommandBatch:
        """The step of N servicers (eqs. 25-28): measurements and link per servicer, the RK4 of the
        internal states and the network over arrays (vectorised.py), grouped by law and hold interval."""
        decoded: dict[tuple[str, bytes], Any] = {}  # each broadcast decoded once for every receiver
        begun = [c._begin(batch.observation(i), decoded) for i, c in enumerate(controllers)]
        groups: dict[tuple[vectorised.Law, float], list[LbdnnServicer]] = {}
        for c, (_eta, dt) in zip(controllers, begun):
            if dt is not None:
                groups.setdefault((c.law(), dt), []).append(c)
        for (_law, dt), group in groups.items():
            cls._propagate_all(group, dt)
        eta = np.array([b[0] for b in begun])
        zeta_hat = np.array([c.zeta_hat for c in controllers])
        phi = np.zeros((len(controllers), 3))
        net = np.array([c.cfg.use_network for c in controllers])
        if net.any():
            rows = np.flatnonzero(net)
            phi[rows] = vectorised.forward(np.concatenate([eta[rows], zeta_hat[rows]], axis=1),
                                           np.array([controllers[r].theta for r in rows.tolist()]), jacobian=False)[0]
        # eq. 25 and 27 over the rows of the servicers that share their gains (elementwise: each row
        # the values of its own call)
        eta_tilde = eta - np.array([c.eta_hat for c in controllers])
        nu = np.array([c.nu for c in controllers])
        rho, law_u = np.empty_like(eta), np.empty_like(eta)
        by_gains: dict[Gains, list[int]] = {}
        for i, c in enumerate(controllers):
            by_gains.setdefault(c.g, []).append(i)
        for g, rows in by_gains.items():
            r = rows if len(rows) < len(controllers) else slice(None)
            rho[r] = rho_filter.rho(eta_tilde[r], nu[r], g)
            law_u[r] = control(phi[r], eta[r], zeta_hat[r], eta_tilde[r], rho[r], g)
        # the thrust-limited variant: the applied (clipped per axis) u is what the observers must see;
        # np.clip's ufunc with each row's bounds
        limits = [c.cfg.max_accel_mps2 for c in controllers]
        limited = [i for i, lim in enumerate(limits) if lim is not None]
        if limited:
            bound = np.array([limits[i] for i in limited], dtype=float)[:, None]
            law_u[limited] = np.clip(law_u[limited], -bound, bound)
        cmds = []
        t = float(batch.t_s)
        for i, c in enumerate(controllers):
            rho_i, u = rho[i], law_u[i]
            c._t_prev, c._eta_prev, c._u_prev = t, eta[i], u
            c.state = InternalState(t, eta[i], c.eta_hat.copy(), c.zeta_hat.copy(), rho_i, c.theta.copy(), phi[i], u)
            payload = packet.encode(packet.StatePacket(batch.step, t, u, c.theta), c.weight_bytes)
            cmds.append(Command(accel_mps2=u, mode="lbdnn",
                                transmissions=[Transmission(type=packet.PACKET_TYPE, payload=payload)]))
        return CommandBatch.of(cmds)


def _decode(payload: bytes) -> packet.StatePacket:
    return packet.decode(bytes(payload))


@register(CONTROLLER)
def make_servicer(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> LbdnnServicer:
    """Scenario factory: the `[controller]` table describes the whole network (the room's contract,
    missions/p004_lbdnn/contract.py `mission_from_params`)."""
    params = dict(params)
    weight_bytes = int(params.pop("weight_bytes", 4))
    return LbdnnServicer(mission_from_params(params).servicer(sc_id), weight_bytes=weight_bytes)
