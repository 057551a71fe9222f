"""The capture agent's flight software: one `step(obs) -> Command` (paper 000 §2–3).

Search (eq. 23): bounce + random walk + APF (+ buffer off the sensed surface); attitude held or
(default) spun slowly about body z so the sensor cone sweeps a band of the sky.
Chase/dock (eq. 24): trigger-held chase PD (eq. 26) toward the buffer slot (eq. 14) + APF +
buffer off the estimated surface, pointing PD at the estimated centroid (eq. 15–18).
Perception at `perception_period_s`: GNC-TLS fit of own and neighbours' pooled returns.
"""
from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from swarmhil.agent.controller import (Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, Transmission, decode_once,
                                        register)
from swarmhil.missions.p000_capture.contract import (POSITION_M, VELOCITY_MPS, Ellipsoid, signed_distance, surface_frame,
                                            surface_frames)

from . import payload as pl
from . import quaternion as quat
from .apf import apf_force, apf_forces, buffer_force
from .attitude import (desired_attitude, desired_attitudes, line_of_sight, pointing_torque, pointing_torques,
                       rate_damping_torque)
from .chase import chase_force
from .estimate import Consensus, TargetEstimate, alpha_beta
from .gnc_tls import GncSettings, gnc_tls_fit, warm_fit
from .limits import norm3, saturate_norm
from .modes import bounce_force, next_mode, random_force
from swarmhil.missions.p000_capture.contract import CaptureParams
from .sensing import CaptureSensing
from .trigger import TriggerSettings, cw_disturbance_bound, fires, fires_rows

log = logging.getLogger("swarmhil.agent")
CONSENSUS_OWN_WEIGHT = 0.8
"""w_ii of eq. 30 for a direct own fit (`consensus`)."""


class CaptureController:
    name = "p000-capture"

    def __init__(self, sc_id: str, orbit: OrbitInfo, params: CaptureParams) -> None:
        self.sc_id = sc_id
        self.p = params
        self.n = orbit.mean_motion_radps
        self.rng = np.random.default_rng(zlib.crc32(sc_id.encode()))
        self.trigger = TriggerSettings()
        self.gnc = GncSettings(noise_bound_m=params.noise_bound_m)
        self.inertia, self.k_q, self.k_w = params.inertia, params.k_q * np.eye(3), params.k_w * np.eye(3)
        self.mode = "search"
        self.own: TargetEstimate | None = None
        self.est: TargetEstimate | None = None
        self.neighbours: dict[str, TargetEstimate] = {}
        self._fused: Consensus | None = None  # eq. 30 of the estimates last fused (`Consensus.holds`)
        self.pool: list[tuple[float, np.ndarray]] = []
        self.last_fit_t = -np.inf
        self.axes_history: list[np.ndarray] = []
        self.settled = False
        self._principal: tuple[bytes, Ellipsoid] | None = None  # the last shape matrix's axes
        self.rnd_force = np.zeros(3)
        self.rnd_t = -np.inf
        self.r_k = self.v_k = None
        self.t_k = -np.inf
        self.held_force = np.zeros(3)
        self.chase_entry_t: float | None = None
        self.broadcasts = 0
        self.fits = 0

    # --- perception -------------------------------------------------------------------------
    def _receive(self, obs: Observation, decoded: dict[tuple[str, bytes], Any] | None = None) -> bool:
        """Neighbours' estimates and landmark returns from the received packets; `decoded`: the
        packets already decoded this step (a broadcast reaches several spacecraft of a batch: each
        payload is decoded once, into arrays nobody modifies)."""
        got = False
        for pkt in obs.isl_rx:
            if pkt.type == pl.STATE_TYPE:
                m = decode_once(decoded, pkt, pl.decode_state)
                if m.centre_m is not None:
                    self.neighbours[pkt.src] = TargetEstimate(m.est_t_s, m.centre_m, m.target_velocity_mps,
                                                              m.shape, direct=False)
                    got = True
            elif pkt.type == pl.LANDMARKS_TYPE:
                self.pool.append(decode_once(decoded, pkt, pl.decode_landmarks))
        return got

    def _fit(self, t: float, r: np.ndarray) -> None:
        self.pool = [(tp, pts) for tp, pts in self.pool if t - tp <= self.p.perception_period_s]
        vel = self.est.velocity_mps if self.est is not None else np.zeros(3)
        pts = np.concatenate([p + vel * (t - tp) for tp, p in self.pool]) if self.pool else np.zeros((0, 3))
        if len(pts) < self.p.fit_min_points:
            return
        if len(pts) > self.p.fit_max_points:
            pts = pts[self.rng.permutation(len(pts))[: self.p.fit_max_points]]
        fit = None
        if self.own is not None:  # warm fit from the own estimate while it explains most points
            try:
                fit = warm_fit(pts, self.own.ellipsoid(t), self.gnc)
                if fit.inliers.mean() < self.p.track_min_inlier_fraction:
                    fit = None
            except ValueError:
                fit = None
        try:
            fit = fit or gnc_tls_fit(pts, self.gnc)
        except ValueError:
            return
        ell = fit.ellipsoid
        self.fits += 1
        ok = (np.all(ell.semi_axes_m > 0.2) and np.all(ell.semi_axes_m < 10.0)
              and fit.inliers.sum() >= self.p.fit_min_points // 2 and signed_distance(ell, r) > 0.0)
        if not ok:
            return
        if self.est is not None:  # innovation gate on the centre (NOTES-000 trap 6)
            pred = self.est.centre_m + self.est.velocity_mps * (t - self.est.t_s)
            if norm3(ell.centre_m - pred) > 1.0 and self.own is not None:
                return
        c, v = alpha_beta(self.own, t, ell.centre_m)
        self.own = TargetEstimate(t, c, v, ell.shape_matrix, direct=True)
        self.axes_history = (self.axes_history + [np.sort(ell.semi_axes_m)])[-self.p.dock_settle_fits:]
        self.settled = self._settled()

    def _settled(self) -> bool:
        h = self.axes_history
        if len(h) < self.p.dock_settle_fits:
            return False
        h = np.array(h)
        return bool(np.all((h.max(axis=0) - h.min(axis=0)) <= self.p.dock_axes_tol * h.mean(axis=0)))

    def _estimate_ellipsoid(self, t: float) -> Ellipsoid:
        """The consensus estimate propagated to t (`TargetEstimate.ellipsoid`), with the principal
        axes of its shape matrix computed once per distinct matrix: between fits and broadcasts the
        consensus M is the same bits every step (raises ValueError if M is not an ellipsoid)."""
        est = self.est
        key = est.shape.tobytes()
        if self._principal is None or self._principal[0] != key:
            self._principal = (key, Ellipsoid.from_shape_matrix(est.centre_m, est.shape))
        axes = self._principal[1]
        return Ellipsoid(est.centre_m + est.velocity_mps * (t - est.t_s), axes.rotation, axes.semi_axes_m)

    # --- control ----------------------------------------------------------------------------
    def _broadcast_due(self, t: float, r: np.ndarray, v: np.ndarray, forced: bool, dt_s: float,
                       fired: bool | None = None) -> bool:
        """`fired`: the event trigger's answer when computed with the other agents' (`fires_rows`)."""
        if forced or self.r_k is None or self.p.broadcast == "every-step":
            return True
        if self.p.broadcast == "periodic":
            return t - self.t_k >= self.p.broadcast_period_s - 0.5 * dt_s
        if fired is not None:
            return fired
        return fires(t, self.r_k, self.v_k, r, v, cw_disturbance_bound(r, v, self.n), self.trigger)

    def step(self, obs: Observation, dt_s: float = 0.05) -> Command:
        s = CaptureSensing.from_dict(obs.extra)
        plan = self._decide(obs, s, dt_s)
        return plan.command(self._torque(s, plan))

    def _torque(self, s: CaptureSensing, plan: "_Plan") -> np.ndarray:
        """The attitude law of a step's plan: rate control in search, else the pointing PD at the
        estimated centre (eq. 15-18)."""
        if plan.los_m is None or plan.ell is None:
            return self._search_torque(s)
        q_d = desired_attitude(s.position_m, plan.ell.centre_m)
        return pointing_torque(s.q_body_to_lvlh, s.omega_body_radps, q_d, self.inertia, self.k_q, self.k_w,
                               self.p.torque_max_nm)

    @classmethod
    def step_batch(cls, controllers: Sequence["CaptureController"], batch: ObservationBatch,
                   dt_s: float = 0.05) -> CommandBatch:
        """Every controller's `step` at once (issue 29), the same command bit for bit. Over arrays:
        the APF (`apf_forces`) and the event trigger (`fires_rows`) from the observations and the
        states before the step, the closest surface point of every estimate (`surface_frames`) and
        the pointing law of every chasing spacecraft (`desired_attitudes`, `pointing_torques`), each
        the per-spacecraft function's operations row by row. Spacecraft by spacecraft, each with its
        own state: perception, fits and consensus (`_perceive`), then slot, mode, chase and packets
        (`_act`). A spacecraft whose software raises (where `step` would) gets a NaN acceleration
        and is listed in `raised`: the batch agents command zero for it and count the fault, as the
        agent node does; nothing that runs after the states change raises for the whole batch."""
        plans: list[_Plan | None] = []
        sensed: list[CaptureSensing | None] = []
        decoded: dict[tuple[str, bytes], Any] = {}
        c0 = controllers[0]
        same_apf = all(c.p.k_r == c0.p.k_r and c.p.r_h_m == c0.p.r_h_m for c in controllers)
        f_col = apf_forces(batch.rel_position_m, batch.offsets, c0.p.k_r, c0.p.r_h_m) if same_apf else None
        fired = cls._fired(controllers, batch)
        n = len(controllers)
        seen: list[_Seen | None] = [None] * n
        obs: list[Observation | None] = [None] * n  # (each made once, for both halves)
        for i, c in enumerate(controllers):  # first halves, then every estimate's closest point at once
            try:
                s = CaptureSensing.from_dict(batch.extra[i] if batch.extra is not None else {})
                o = obs[i] = batch.observation(i)
                seen[i] = c._perceive(o, s, decoded)
                sensed.append(s)
            except Exception:  # noqa: BLE001 - as `step` raising in an agent node: this one commands zero
                log.exception("%s: p000-capture raised at step %d; commanding zero", c.sc_id, batch.step)
                sensed.append(None)
        frames = cls._frames(seen, sensed)
        for i, c in enumerate(controllers):
            sn, s_i = seen[i], sensed[i]
            if sn is None or s_i is None:
                plans.append(None)
                continue
            try:
                frame = frames[i] if frames[i] is not None or sn.ell is None else surface_frame(sn.ell, s_i.position_m)
                plans.append(c._act(obs[i], s_i, dt_s, sn, frame,  # type: ignore[arg-type]
                                    None if f_col is None else f_col[i], fired[i]))
            except Exception:  # noqa: BLE001 - as above
                log.exception("%s: p000-capture raised at step %d; commanding zero", c.sc_id, batch.step)
                plans.append(None)
        torque = np.zeros((n, 3))
        pointing = [i for i, pl_ in enumerate(plans) if pl_ is not None and pl_.los_m is not None]
        done: set[int] = set()
        if pointing and all(c.p.torque_max_nm == c0.p.torque_max_nm and c.p.inertia_kgm2 == c0.p.inertia_kgm2
                            and c.p.k_q == c0.p.k_q and c.p.k_w == c0.p.k_w for c in controllers):
            q = np.array([sensed[i].q_body_to_lvlh for i in pointing])  # type: ignore[union-attr]
            w = np.array([sensed[i].omega_body_radps for i in pointing])  # type: ignore[union-attr]
            los = np.array([plans[i].los_m for i in pointing])  # type: ignore[union-attr]
            try:
                torque[pointing] = pointing_torques(q, w, desired_attitudes(los), c0.p.inertia_kgm2, c0.p.k_q,
                                                    c0.p.k_w, c0.p.torque_max_nm)
                done = set(pointing)
            except Exception:  # noqa: BLE001 - each its own law below, where one raises as in `step`
                done = set()
        for i, pl_ in enumerate(plans):  # the search law, and each its own where not done above
            if pl_ is None or i in done:
                continue
            try:
                torque[i] = controllers[i]._torque(sensed[i], pl_)  # type: ignore[arg-type]
            except Exception:  # noqa: BLE001 - as `step` raising in an agent node
                log.exception("%s: p000-capture raised at step %d; commanding zero", controllers[i].sc_id, batch.step)
                plans[i] = None
        acc = np.full((n, 3), np.nan)
        for i, pl_ in enumerate(plans):
            if pl_ is not None:
                acc[i] = pl_.force_n / controllers[i].p.mass_kg
        modes = [pl_.mode if pl_ is not None else "fault" for pl_ in plans]

        def build(i: int) -> Command:
            pl_ = plans[i]
            if pl_ is None:
                return Command(accel_mps2=acc[i].copy(), mode="fault")
            return pl_.command(torque[i].copy())

        def sent(i: int) -> list[Transmission]:  # build(i).transmissions
            pl_ = plans[i]
            return [] if pl_ is None else pl_.transmissions

        return CommandBatch(accel_mps2=acc, modes=modes, build=build, torque_nm=torque,
                            raised=tuple(i for i, pl_ in enumerate(plans) if pl_ is None), sent=sent)

    @staticmethod
    def _frames(seen: list["_Seen | None"], sensed: list[CaptureSensing | None]
                ) -> list[tuple[float, np.ndarray, np.ndarray] | None]:
        """surface_frame(ell, r) of every agent that flies on an estimate, at once (`surface_frames`:
        the same bits row by row); None for the others."""
        rows = [i for i, sn in enumerate(seen) if sn is not None and sn.ell is not None]
        out: list[tuple[float, np.ndarray, np.ndarray] | None] = [None] * len(seen)
        if not rows:
            return out
        ells = [seen[i].ell for i in rows]  # type: ignore[union-attr]
        try:
            sd, x_s, nrm = surface_frames(ells, np.array([sensed[i].position_m for i in rows]))  # type: ignore[misc, union-attr]
        except Exception:  # noqa: BLE001 - each its own in `step_batch`'s second loop (raising there as in `step`)
            return out
        for k, i in enumerate(rows):
            out[i] = (float(sd[k]), x_s[k], nrm[k])
        return out

    @staticmethod
    def _fired(controllers: Sequence["CaptureController"], batch: ObservationBatch) -> list[bool | None]:
        """The event trigger (eq. 27-29) of every agent that has a last broadcast state, over arrays
        (`fires_rows`), from its own state and measurement before its step; None for the others
        (their `_broadcast_due` decides without it, or the measurement is malformed: `step` raises)."""
        out: list[bool | None] = [None] * len(controllers)
        rows, rk, vk, r, v = [], [], [], [], []
        for i, c in enumerate(controllers):
            extra = batch.extra[i] if batch.extra is not None else {}
            if c.r_k is None or c.p.broadcast != "event" or POSITION_M not in extra or VELOCITY_MPS not in extra:
                continue
            ri, vi = np.asarray(extra[POSITION_M], dtype=float), np.asarray(extra[VELOCITY_MPS], dtype=float)
            if ri.shape != (3,) or vi.shape != (3,):
                continue
            rows.append(i)
            rk.append(c.r_k)
            vk.append(c.v_k)
            r.append(ri)
            v.append(vi)
        if not rows:
            return out
        c0 = controllers[rows[0]]
        if any(controllers[i].n != c0.n or controllers[i].trigger != c0.trigger for i in rows):
            return out  # (per-agent settings: each decides alone)
        got = fires_rows(batch.t_s, np.array(rk), np.array(vk), np.array(r), np.array(v), c0.n, c0.trigger)
        for i, f in zip(rows, got.tolist()):
            out[i] = f
        return out

    def _search_torque(self, s: CaptureSensing) -> np.ndarray:
        p = self.p
        scan = np.array([0.0, 0.0, np.radians(p.scan_rate_dps)]) if p.search_attitude == "scan" else None
        return rate_damping_torque(s.omega_body_radps, self.inertia, self.k_w, p.torque_max_nm, scan)

    def _decide(self, obs: Observation, s: CaptureSensing, dt_s: float,
                decoded: dict[tuple[str, bytes], Any] | None = None, f_col_n: np.ndarray | None = None,
                fired: bool | None = None) -> "_Plan":
        """Everything of a step but the attitude torque: perception, consensus, mode, force, packets.
        The pointing law's line of sight is checked here, where `step` computes it. `f_col_n`,
        `fired`: the APF force and the event trigger's answer when computed with the other agents'
        (`apf_forces`, `fires_rows`: both read only the observation and the state before the step)."""
        seen = self._perceive(obs, s, decoded)
        return self._act(obs, s, dt_s, seen, None if seen.ell is None else surface_frame(seen.ell, s.position_m),
                         f_col_n, fired)

    def _perceive(self, obs: Observation, s: CaptureSensing,
                  decoded: dict[tuple[str, bytes], Any] | None = None) -> "_Seen":
        """A step's first half: packets, landmarks (shared, fitted at 1 Hz), consensus, and the
        estimate flown on (`_Seen`); the closest surface point of it comes next (`_act`'s `frame`)."""
        t, r = obs.t_s, s.position_m
        p = self.p
        received = self._receive(obs, decoded)
        txs: list[Transmission] = []
        returns = len(s.landmarks_body_m)
        detected = returns >= p.detect_min_returns
        if detected and t - self.last_fit_t >= p.perception_period_s - 1e-9:  # (the returns in LVLH only here)
            lm = r + quat.rotate(s.q_body_to_lvlh, s.landmarks_body_m) if returns else np.zeros((0, 3))
            self.pool.append((t, lm))
            share = lm[self.rng.permutation(len(lm))[: p.landmarks_per_packet]]
            txs.append(Transmission(pl.LANDMARKS_TYPE, pl.encode_landmarks(t, share)))
            self._fit(t, r)
            self.last_fit_t = t
        fresh = [e for src, e in self.neighbours.items() if t - e.t_s <= p.estimate_max_age_s]
        had_estimate = self.est is not None
        own = self.own if self.own is not None and t - self.own.t_s <= p.estimate_max_age_s else None
        fused = self._fused
        if fused is None or not fused.holds(own, fresh, CONSENSUS_OWN_WEIGHT):
            fused = self._fused = Consensus.of(own, fresh, CONSENSUS_OWN_WEIGHT)
        self.est = (None if fused is None else fused.at(t)) or self.est  # = consensus(own, fresh, t, 0.8)
        ell = None
        if self.est is not None:
            try:
                ell = self._estimate_ellipsoid(t)
            except ValueError:
                ell = None
        return _Seen(ell, detected, received, had_estimate, txs)

    def _act(self, obs: Observation, s: CaptureSensing, dt_s: float, seen: "_Seen",
             frame: tuple[float, np.ndarray, np.ndarray] | None, f_col_n: np.ndarray | None = None,
             fired: bool | None = None) -> "_Plan":
        """A step's second half, from `_perceive`'s `seen` and the closest point of its estimate
        (`frame`: surface_frame(seen.ell, r), None without one): slot, mode, forces, the broadcast."""
        t, r, v = obs.t_s, s.position_m, s.velocity_mps
        p = self.p
        ell, detected, received, had_estimate, txs = seen.ell, seen.detected, seen.received, seen.had_estimate, seen.txs
        slot = None
        if ell is not None and frame is not None:
            sd, x_s, nrm = frame
            slot = x_s + p.r_buffer_m * nrm  # eq. 14
        old_mode = self.mode
        at_slot = slot is not None and norm3(r - slot) < p.dock_slot_tol_m
        self.mode = next_mode(self.mode, detected, received, self.settled, at_slot)
        if self.mode != "search" and ell is None:
            self.mode = "search" if old_mode == "search" else self.mode
        entered = old_mode == "search" and self.mode != "search"
        if entered:
            self.chase_entry_t = t

        f_col = apf_force(obs.rel_position_m, p.k_r, p.r_h_m) if f_col_n is None else f_col_n
        if self.mode == "search" or ell is None:
            if t - self.rnd_t >= p.random_redraw_s:
                self.rnd_force, self.rnd_t = random_force(self.rng, p.random_alpha, p.f_thr_n), t
            force = bounce_force(r, p.search_box_m, p.f_thr_n) + self.rnd_force + f_col
            if s.surface_rel_m is not None:
                d = norm3(s.surface_rel_m)
                force = force + buffer_force(d, -s.surface_rel_m / max(d, 1e-9), v, p.k_r_target,
                                             p.r_buffer_m, p.buffer_damping_nspm)
            los = None
        else:
            forced = entered or not had_estimate
            if self._broadcast_due(t, r, v, forced, dt_s, fired):
                e_max = p.approach_speed_mps * p.k_v / p.k_p if p.chase_law == "governed" else None
                self.held_force = chase_force(r, v, slot, self.est.velocity_mps, p.k_p, p.k_v, e_max)
                self.r_k, self.v_k, self.t_k = r.copy(), v.copy(), t
                msg = pl.StateMsg(t, self.mode, r, v, self.est.t_s, self.est.centre_m, self.est.velocity_mps,
                                  self.est.shape)
                txs.append(Transmission(pl.STATE_TYPE, pl.encode_state(msg)))
                self.broadcasts += 1
            force = self.held_force + f_col + buffer_force(sd, nrm, v - self.est.velocity_mps, p.k_r_target,
                                                           p.r_buffer_m, p.buffer_damping_nspm)
            los = line_of_sight(r, ell.centre_m)  # (raises where desired_attitude would)
        return _Plan(saturate_norm(force, p.force_max_n), p.mass_kg, self.mode, txs, ell,
                     sd if ell is not None else 0.0, los)


@dataclass
class _Seen:
    """`_perceive`'s answer: the estimate flown on (None: none yet, or not an ellipsoid), whether
    the agent detected the target or received an estimate, had one before, and its packets so far."""

    ell: Ellipsoid | None
    detected: bool
    received: bool
    had_estimate: bool
    txs: list[Transmission]


@dataclass
class _Plan:
    """A step's decision but the torque: the saturated force, mode, packets, the estimate it flew
    on and the line of sight of the pointing law (None: search, rate control)."""

    force_n: np.ndarray
    mass_kg: float
    mode: str
    transmissions: list[Transmission]
    ell: Ellipsoid | None
    surface_m: float
    los_m: np.ndarray | None

    def command(self, torque_nm: np.ndarray) -> Command:
        ell = self.ell
        extra = {} if ell is None else {  # what the agent believes, for the report (Figs. 7, 12)
            "p000_axes_est_m": np.sort(ell.semi_axes_m), "p000_centre_est_m": ell.centre_m,
            "p000_surface_est_m": np.array([self.surface_m])}
        return Command(accel_mps2=self.force_n / self.mass_kg, mode=self.mode, transmissions=self.transmissions,
                       torque_nm=torque_nm, extra=extra)


@register("p000-capture")
def make_capture(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> CaptureController:
    return CaptureController(sc_id, orbit, CaptureParams.from_dict(params))
