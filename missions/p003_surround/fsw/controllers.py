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

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmhil.agent.controller import (Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, Transmission, decode_once,
                                        register)
from swarmhil.missions.p003_surround.fsw import nash, packets, sensing, vectorised
from swarmhil.missions.p003_surround.fsw.funnel import clip_norm_rows, leader_accel, tt_control
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


_KINDS: dict[tuple[Any, ...], int] = {}  # ServicerController._kind -> its number


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
        self._telemetry: ServicerTelemetry | tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] = ServicerTelemetry()
        self._kind_number: int | None = None
        self._views: _Views | None = None  # x_err and xi as rows of the arrays of the servicers stepped with it

    @property
    def telemetry(self) -> ServicerTelemetry:
        """The terms of the last command (eq. 6) and whether the thrust limit cut it, made when read
        from the rows its step kept (k, u_sync, u_ct, u_id, the limited u, their sum): a batch run
        reads none of it (issue 29)."""
        t = self._telemetry
        if not isinstance(t, ServicerTelemetry):
            k, u_sync, u_ct, u_id, u, total = t
            t = self._telemetry = ServicerTelemetry(u_sync[k], u_ct[k], u_id[k], u[k], not _allclose(u[k], total[k]))
        return t

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

    def _kind_id(self) -> int:
        """A number for `_kind` (equal kinds, equal numbers), made at the first step (the game, slots,
        spheres and ξ's shape are set at construction): grouping without hashing the game each step."""
        if self._kind_number is None:
            self._kind_number = _KINDS.setdefault(self._kind(), len(_KINDS))
        return self._kind_number

    @classmethod
    def step_batch(cls, controllers: list["ServicerController"], batch: ObservationBatch) -> CommandBatch:
        """The step of S servicers, grouped by what they share: first every group's packets and
        measurements into its stacked views (`_Views`: what may raise, before any state moves on),
        then the Nash CT gradient and the ξ rate of eq. 18-20 over arrays (vectorised.py) and each
        group's commands."""
        t_s = float(batch.t_s)
        extra, isl_rx = batch.extra, batch.isl_rx
        decoded: dict[tuple[str, bytes], Any] = {}  # each broadcast decoded once for every receiver
        shared: dict[tuple[int, float, bytes], np.ndarray] = {}  # the centres of one TT packet (read-only here)
        groups: dict[int, list[int]] = {}
        for r, c in enumerate(controllers):
            groups.setdefault(c._kind_id(), []).append(r)
        ready = []
        for rows in groups.values():
            cs = [controllers[r] for r in rows]
            views = _Views.of(cs)
            views.receive([isl_rx[r] if isl_rx is not None else [] for r in rows], decoded)
            pos, vel = sensing.read_rows([extra[r] if extra is not None else {} for r in rows], LEADER_REL_KEY)
            views.measure(pos, vel)
            ready.append((rows, cs, views, pos, vel, views.centres(t_s, shared)))
        cmds: list[Command] = [None] * len(controllers)  # type: ignore[list-item]
        accel = np.empty((len(controllers), 3))
        for rows, cs, views, pos, vel, centres in ready:
            gx, rt = vectorised.grad_and_xi_rate(views.x_err, views.xi, cs[0].slots_m, centres, cs[0].r_g_m, views.own, cs[0].g)
            accel[rows], group = cls._commands(cs, views, pos, vel, gx, rt, t_s)
            for r, cmd in zip(rows, group):
                cmds[r] = cmd
        # (CommandBatch.of(cmds): every acceleration a 3-vector, no torque)
        return CommandBatch(accel_mps2=accel, modes=[c.mode for c in cmds], build=cmds.__getitem__)

    @staticmethod
    def _commands(cs: list["ServicerController"], views: "_Views", pos: np.ndarray, vel: np.ndarray,
                  grad: np.ndarray, rate: np.ndarray, t_s: float) -> tuple[np.ndarray, list[Command]]:
        """u_i = u_Li + u_ci* + u_id (eq. 6) of servicers that share their game, from their ∂V_i/∂x~_i
        (grad, (S, 6)) and measured states (pos, vel, (S, 3)), then the Euler step of each one's ξ_i
        (eq. 20) at its ξ rate (rate, (S, 6)). Over rows, each row the arithmetic of one servicer
        alone: elementwise, the natural relative acceleration's |r| a sum along the last axis, each
        norm of the saturations its own `clip_norm`'s (`clip_norm_rows`). Servicer by servicer, in
        order: its telemetry, its clock, its ξ_i, its packet (so a packet that cannot be encoded
        leaves the servicers before it stepped, as one `step` each would). Returns the accelerations
        (S, 3) and the commands."""
        g, m = cs[0].g, cs[0].g.mass_kg
        u_ct = m * nash.ct_accel(grad, g)
        o0, tt0 = cs[0].orbit, cs[0].tt
        if g.cancel_natural and all(c.orbit is o0 for c in cs):  # (one orbit, as a scenario's servicers share)
            u_id = -m * natural_rel_accel(pos, vel, o0.semi_major_axis_m, o0.mean_motion_radps)
        else:
            u_id = np.zeros((len(cs), 3))
            by_orbit: dict[OrbitInfo, list[int]] = {}
            for k, c in enumerate(cs if g.cancel_natural else []):
                by_orbit.setdefault(c.orbit, []).append(k)
            for orbit, ks in by_orbit.items():
                u_id[ks] = -m * natural_rel_accel(pos[ks], vel[ks], orbit.semi_major_axis_m, orbit.mean_motion_radps)
        if tt0 is not None and all(c.tt is tt0 for c in cs):  # (one TT packet, as a step's broadcast)
            u_sync = m * np.broadcast_to(tt0.leader_accel_mps2, (len(cs), 3))
        else:
            u_sync = m * np.array([c.tt.leader_accel_mps2 if c.tt is not None else np.zeros(3) for c in cs])
        total = u_sync + u_ct + u_id
        u = clip_norm_rows(total, g.max_thrust_n) if g.saturate == "sum" else u_sync + clip_norm_rows(u_ct + u_id, g.max_thrust_n)
        xi_rate = rate.copy()
        xi_rate[:, :3] = clip_norm_rows(rate[:, :3], g.xi_rate_cap_mps)  # the position rate capped (guard)
        accel = u / m
        # explicit Euler step of eq. 20 for each own block ξ_i (dt: each servicer's own clock)
        dt = np.array([0.0 if c.t_prev is None else t_s - c.t_prev for c in cs])
        rows, own = views.rows, views.own
        xi_own = views.xi[rows, own] + dt[:, None] * xi_rate
        values = np.concatenate((views.x_err[rows, own], xi_own), axis=1).tolist()  # each packet's x~_i, ξ_i
        out = []
        for k, c in enumerate(cs):
            c._telemetry = (k, u_sync, u_ct, u_id, u, total)
            c.t_prev = t_s
            c.xi[c.index] = xi_own[k]
            out.append(Command(accel_mps2=accel[k], mode="surround",
                               transmissions=[Transmission(packets.CT_TYPE, packets.encode_ct_values(c.index, values[k]))]))
        return accel, out


class _Views:
    """The x~ and ξ (N, 6) of S servicers stepped together, stacked (S, N, 6): each servicer's own
    `x_err` and `xi` are rows (views) of these, so a step reads and writes them without a copy per
    servicer (issue 29). Made when the servicers first step together (their arrays copied in, then
    theirs rebound to the rows) and again whenever they are not exactly these rows any more."""

    __slots__ = ("members", "x_err", "xi", "x_rows", "xi_rows", "rows", "own")

    def __init__(self, cs: list[ServicerController]) -> None:
        self.members = tuple(cs)
        self.x_err, self.xi = np.array([c.x_err for c in cs], dtype=float), np.array([c.xi for c in cs], dtype=float)
        self.x_rows, self.xi_rows = list(self.x_err), list(self.xi)
        self.rows, self.own = np.arange(len(cs)), np.array([c.index for c in cs])
        for c, x, xi in zip(cs, self.x_rows, self.xi_rows):
            c.x_err, c.xi, c._views = x, xi, self

    @classmethod
    def of(cls, cs: list[ServicerController]) -> "_Views":
        """The views of `cs` (in this order): the ones they share, if they still hold their rows."""
        v = cs[0]._views
        if (v is not None and v.members == tuple(cs)
                and all(c.x_err is x and c.xi is xi for c, x, xi in zip(cs, v.x_rows, v.xi_rows))):
            return v
        return cls(cs)

    def receive(self, isl_rx: list[list[Any]], decoded: dict[tuple[str, bytes], Any]) -> None:
        """Each servicer's packets received, in order: the leader's last TT packet (`tt`, `tt_sent_t`)
        and the other servicers' x~_j, ξ_j (rows j of its view; the last packet of each j). `decoded`:
        the payloads already decoded this step (agent/controller.py `decode_once`); each CT packet's
        values made an array once (a row of `table`) for all its receivers."""
        n = self.x_err.shape[1]
        tt_type, ct_type, decode_tt = packets.TT_TYPE, packets.CT_TYPE, packets.decode_tt
        row_of: dict[tuple[str, bytes], tuple[int, int]] = {}  # a CT packet -> (its j, its row of `table`)
        table: list[tuple[float, ...]] = []
        ks: list[int] = []
        js: list[int] = []
        rows: list[int] = []
        for k, (c, rx) in enumerate(zip(self.members, isl_rx)):
            got: dict[int, int] = {}  # j -> the row of its last packet
            for pkt in rx:
                typ = pkt.type
                if typ == ct_type:
                    key = (typ, pkt.payload)
                    hit = row_of.get(key)
                    if hit is None:
                        j, values = decode_once(decoded, pkt, packets.decode_ct_values)
                        hit = row_of[key] = (j, len(table))
                        table.append(values)
                    j, row = hit
                    if j != c.index and 0 <= j < n:
                        got[j] = row
                elif typ == tt_type:
                    c.tt, c.tt_sent_t = decode_once(decoded, pkt, decode_tt), float(pkt.sent_t)
            ks += [k] * len(got)
            js += got
            rows += got.values()
        if ks:
            v = np.array(table, dtype=float)[rows]
            self.x_err[ks, js], self.xi[ks, js] = v[:, :6], v[:, 6:]

    def measure(self, pos: np.ndarray, vel: np.ndarray) -> None:
        """Each servicer's own row of x~: its measured q_Li - q_Li,d and q'_Li (pos, vel: (S, 3))."""
        rows, own = self.rows, self.own
        self.x_err[rows, own, :3] = pos - self.members[0].slots_m[own]
        self.x_err[rows, own, 3:] = vel

    def centres(self, t_s: float, shared: dict[tuple[int, float, bytes], np.ndarray]) -> np.ndarray:
        """(S, G, 3) each servicer's sphere centres (`_sphere_centres`): one read-only broadcast when
        they share one TT packet; `shared` holds each packet's centres for this step."""
        got = []
        for c in self.members:
            key = (id(c.tt), c.tt_sent_t, c.d_cg_m.tobytes())
            centres = shared.get(key)
            if centres is None:
                centres = shared[key] = c._sphere_centres(t_s)
            got.append(centres)
        if all(x is got[0] for x in got):
            return np.broadcast_to(got[0], (len(got),) + got[0].shape)
        return np.array(got)


def _allclose(a: np.ndarray, b: np.ndarray) -> bool:
    """np.allclose(a, b) (rtol 1e-5, atol 1e-8) without its Python when a and b are finite: np.isclose
    is then |a - b| <= 1e-8 + 1e-5 |b| (or a == b, which implies it) everywhere; otherwise
    np.allclose itself (issue 29: ~25 us a servicer and step)."""
    if math.isfinite(np.add.reduce(a) + np.add.reduce(b)):  # finite sums: every entry finite
        return bool((np.abs(a - b) <= 1e-8 + 1e-5 * np.abs(b)).all())
    return bool(np.allclose(a, b))


@register(LEADER_CONTROLLER)
def make_leader(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> LeaderController:
    return LeaderController(from_dict(FunnelParams, params.get("funnel")))


@register(SERVICER_CONTROLLER)
def make_servicer(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> ServicerController:
    return ServicerController(servicer_index(sc_id, params), orbit,
                              from_dict(FunnelParams, params.get("funnel")),
                              from_dict(GameParams, params.get("game")))
