"""The two flight-software controllers of paper 003, registered as "p003-leader" and
"p003-servicer" (agent.controller registry).

Leader (LSat): measures q_TL, q'_TL (TARGET_REL_KEY), runs the funnel TT controller
(eq. 15-17), thrusts -u_L (<= 180 N) and broadcasts a `p003.tt` packet each step.
Servicer (SSat i): measures q_Li, q'_Li (LEADER_REL_KEY), receives the leader's `p003.tt`
and the other servicers' `p003.ct`, and thrusts u_i = u_Li + u_ci* + u_id (eq. 6): the synchronous
term m_i a_L, the Nash CT control (eq. 21) and the cancellation of the natural relative motion,
limited to 20 N; it keeps its block ξ_i of the immersion variable (eq. 20) and broadcasts it.
All vectors in the leader's LVLH (x radial, y along-track, z orbit normal).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, Transmission, register
from swarmhil.missions.p003_surround.fsw import nash, packets, sensing, vectorised
from swarmhil.missions.p003_surround.fsw.funnel import clip_norm, leader_accel, tt_control
from swarmhil.missions.p003_surround.contract import (
    LEADER_CONTROLLER,
    LEADER_REL_KEY,
    SERVICER_CONTROLLER,
    SLOT_OFFSETS_M,
    TARGET_REL_KEY,
    FunnelParams,
    GameParams,
    from_dict,
    q_des,
    servicer_index,
    slots_in_leader_frame,
    sphere_arrays,
)
from swarmhil.missions.p003_surround.fsw.relative_dynamics import natural_rel_accel

XI0_PAPER: np.ndarray = np.array([
    [5.0, 0, 0, 0, 0, 0], [1.0, 0, 0, 0, 0, 0], [0, 4.0, 0, 0, 0, 0],
    [0, 1.0, 0, 0, 0, 0], [0, 0, 5.0, 0, 0, 0], [0, 0, 2.0, 0, 0, 0],
])
"""ξ(0) of §5 (m and m/s; printed without signs, taken positive)."""


@dataclass
class LeaderTelemetry:
    u_l_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    e1: np.ndarray = field(default_factory=lambda: np.zeros(3))
    e2: np.ndarray = field(default_factory=lambda: np.zeros(3))


class LeaderController:
    """Funnel target tracking on the leader (eq. 15-17)."""

    name = "p003-leader"

    def __init__(self, p: FunnelParams) -> None:
        self.p = p
        self.telemetry = LeaderTelemetry()
        self.t_prev: float | None = None

    def step(self, obs: Observation) -> Command:
        target = sensing.read(obs.extra, TARGET_REL_KEY)
        # the hold of the discrete-time guard: the measured interval between steps (p.sample_s first)
        hold = self.p.sample_s if self.t_prev is None or obs.t_s <= self.t_prev else obs.t_s - self.t_prev
        self.t_prev = obs.t_s
        u_l, e1, e2 = tt_control(target.position_m, target.velocity_mps, obs.t_s, self.p, hold)
        accel = leader_accel(u_l, self.p)
        self.telemetry = LeaderTelemetry(u_l, e1, e2)
        pkt = packets.TTPacket(obs.step, accel, target.position_m, target.velocity_mps)
        return Command(accel_mps2=accel, mode="track",
                       transmissions=[Transmission(packets.TT_TYPE, packets.encode_tt(pkt))])


@dataclass
class ServicerTelemetry:
    u_sync_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    u_ct_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    u_id_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    u_applied_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    saturated: bool = False


class ServicerController:
    """Nash CT control of servicer `index` (eq. 6, 18-21)."""

    name = "p003-servicer"

    def __init__(self, index: int, orbit: OrbitInfo, f: FunnelParams, g: GameParams,
                 slot_offsets_m: np.ndarray = SLOT_OFFSETS_M, xi0: np.ndarray = XI0_PAPER) -> None:
        self.index = index
        self.orbit = orbit
        self.g = g
        self.slots_m = slots_in_leader_frame(q_des(f), slot_offsets_m)
        if not 0 <= index < len(self.slots_m):
            raise ValueError(f"servicer index {index} outside 0..{len(self.slots_m) - 1}")
        self.d_cg_m, self.r_g_m = sphere_arrays()
        self.xi = np.array(xi0, dtype=float)  # own row is state; other rows: last received
        self.x_err = np.zeros_like(self.xi)
        self.tt: packets.TTPacket | None = None
        self.tt_sent_t = 0.0
        self.t_prev: float | None = None
        self.telemetry = ServicerTelemetry()

    def _receive(self, obs: Observation) -> None:
        for pkt in obs.isl_rx:
            if pkt.type == packets.TT_TYPE:
                self.tt, self.tt_sent_t = packets.decode_tt(pkt.payload), float(pkt.sent_t)
            elif pkt.type == packets.CT_TYPE:
                ct = packets.decode_ct(pkt.payload)
                if ct.index != self.index and 0 <= ct.index < len(self.xi):
                    self.x_err[ct.index], self.xi[ct.index] = ct.x_err, ct.xi

    def _sphere_centres(self, t_s: float) -> np.ndarray:
        """q_Cg = q_TL + d_Cg, q_TL from the leader's packet carried forward to t (§5)."""
        if self.tt is None:  # structure not yet reported: no structure threat
            return np.full_like(self.d_cg_m, 1e12)
        q_tl = self.tt.q_tl_m + self.tt.v_tl_mps * (t_s - self.tt_sent_t)
        return q_tl[None, :] + self.d_cg_m

    def step(self, obs: Observation) -> Command:
        """Eq. 6, 18-21 for this servicer: the batch path with S = 1 (`step_batch`), so that an agent
        process and a batch run give the same command, bit for bit."""
        return self.step_batch([self], ObservationBatch.of([str(self.index)], [obs])).command(0)

    def _kind(self) -> tuple[Any, ...]:
        """What servicers must share to be stepped in one call (vectorised.py)."""
        return (self.g, self.slots_m.tobytes(), self.r_g_m.tobytes(), self.xi.shape)

    @classmethod
    def step_batch(cls, controllers: list["ServicerController"], batch: ObservationBatch) -> CommandBatch:
        """The step of S servicers: packets and measurements per servicer, the Nash CT gradient and
        the ξ rate of eq. 18-20 over arrays (vectorised.py), grouped by what they share."""
        t_s = float(batch.t_s)
        mes, centres = [], []
        for r, c in enumerate(controllers):
            obs = batch.observation(r)
            c._receive(obs)
            me = sensing.read(obs.extra, LEADER_REL_KEY)
            c.x_err[c.index] = np.concatenate([me.position_m - c.slots_m[c.index], me.velocity_mps])
            mes.append(me)
            centres.append(c._sphere_centres(t_s))
        groups: dict[tuple[Any, ...], list[int]] = {}
        for r, c in enumerate(controllers):
            groups.setdefault(c._kind(), []).append(r)
        grads, rates = [np.zeros(6)] * len(controllers), [np.zeros(6)] * len(controllers)
        for rows in groups.values():
            cs = [controllers[r] for r in rows]
            gx, rt = vectorised.grad_and_xi_rate(np.array([c.x_err for c in cs]), np.array([c.xi for c in cs]),
                                                 cs[0].slots_m, np.array([centres[r] for r in rows]), cs[0].r_g_m,
                                                 np.array([c.index for c in cs]), cs[0].g)
            for k, r in enumerate(rows):
                grads[r], rates[r] = gx[k], rt[k]
        cmds = [c._command(mes[r], grads[r], rates[r], t_s) for r, c in enumerate(controllers)]
        return CommandBatch.of(cmds)

    def _command(self, me: Any, grad: np.ndarray, rate: np.ndarray, t_s: float) -> Command:
        """u_i = u_Li + u_ci* + u_id (eq. 6) from ∂V_i/∂x~_i, then the Euler step of ξ_i (eq. 20)."""
        i, g, m = self.index, self.g, self.g.mass_kg
        u_ct = m * nash.ct_accel(grad, g)
        u_id = (-m * natural_rel_accel(me.position_m, me.velocity_mps, self.orbit.semi_major_axis_m,
                                       self.orbit.mean_motion_radps) if g.cancel_natural else np.zeros(3))
        u_sync = m * (self.tt.leader_accel_mps2 if self.tt is not None else np.zeros(3))
        if g.saturate == "sum":
            u = clip_norm(u_sync + u_ct + u_id, g.max_thrust_n)
        else:
            u = u_sync + clip_norm(u_ct + u_id, g.max_thrust_n)
        saturated = not np.allclose(u, u_sync + u_ct + u_id)
        self.telemetry = ServicerTelemetry(u_sync, u_ct, u_id, u, saturated)
        # explicit Euler step of eq. 20 for the own block ξ_i, position rate capped (guard)
        dt = 0.0 if self.t_prev is None else t_s - self.t_prev
        self.t_prev = t_s
        rate = rate.copy()
        rate[:3] = clip_norm(rate[:3], self.g.xi_rate_cap_mps)
        self.xi[i] = self.xi[i] + dt * rate
        pkt = packets.CTPacket(i, self.x_err[i], self.xi[i])
        return Command(accel_mps2=u / m, mode="surround",
                       transmissions=[Transmission(packets.CT_TYPE, packets.encode_ct(pkt))])


@register(LEADER_CONTROLLER)
def make_leader(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> LeaderController:
    return LeaderController(from_dict(FunnelParams, params.get("funnel")))


@register(SERVICER_CONTROLLER)
def make_servicer(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> ServicerController:
    return ServicerController(servicer_index(sc_id, params), orbit,
                              from_dict(FunnelParams, params.get("funnel")),
                              from_dict(GameParams, params.get("game")))
