"""The capture agent's flight software: one `step(obs) -> Command` (paper 000 §2–3).

Search (eq. 23): bounce + random walk + APF (+ buffer off the sensed surface); attitude held or
(default) spun slowly about body z so the sensor cone sweeps a band of the sky.
Chase/dock (eq. 24): trigger-held chase PD (eq. 26) toward the buffer slot (eq. 14) + APF +
buffer off the estimated surface, pointing PD at the estimated centroid (eq. 15–18).
Perception at `perception_period_s`: GNC-TLS fit of own and neighbours' pooled returns.
"""
from __future__ import annotations

import zlib
from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, Observation, OrbitInfo, Transmission, register
from swarmhil.missions.p000_capture.contract import Ellipsoid, signed_distance, surface_frame

from . import payload as pl
from . import quaternion as quat
from .apf import apf_force, buffer_force
from .attitude import desired_attitude, pointing_torque, rate_damping_torque
from .chase import chase_force
from .estimate import TargetEstimate, alpha_beta, consensus
from .gnc_tls import GncSettings, gnc_tls_fit, warm_fit
from .limits import norm3, saturate_norm
from .modes import bounce_force, next_mode, random_force
from swarmhil.missions.p000_capture.contract import CaptureParams
from .sensing import CaptureSensing
from .trigger import TriggerSettings, cw_disturbance_bound, fires


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
    def _receive(self, obs: Observation) -> bool:
        got = False
        for pkt in obs.isl_rx:
            if pkt.type == pl.STATE_TYPE:
                m = pl.decode_state(pkt.payload)
                if m.centre_m is not None:
                    self.neighbours[pkt.src] = TargetEstimate(m.est_t_s, m.centre_m, m.target_velocity_mps,
                                                              m.shape, direct=False)
                    got = True
            elif pkt.type == pl.LANDMARKS_TYPE:
                self.pool.append(pl.decode_landmarks(pkt.payload))
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
    def _broadcast_due(self, t: float, r: np.ndarray, v: np.ndarray, forced: bool, dt_s: float) -> bool:
        if forced or self.r_k is None or self.p.broadcast == "every-step":
            return True
        if self.p.broadcast == "periodic":
            return t - self.t_k >= self.p.broadcast_period_s - 0.5 * dt_s
        return fires(t, self.r_k, self.v_k, r, v, cw_disturbance_bound(r, v, self.n), self.trigger)

    def step(self, obs: Observation, dt_s: float = 0.05) -> Command:
        s = CaptureSensing.from_dict(obs.extra)
        t, r, v = obs.t_s, s.position_m, s.velocity_mps
        p = self.p
        received = self._receive(obs)
        txs: list[Transmission] = []
        lm = r + quat.rotate(s.q_body_to_lvlh, s.landmarks_body_m) if len(s.landmarks_body_m) else np.zeros((0, 3))
        detected = len(lm) >= p.detect_min_returns
        if detected and t - self.last_fit_t >= p.perception_period_s - 1e-9:
            self.pool.append((t, lm))
            share = lm[self.rng.permutation(len(lm))[: p.landmarks_per_packet]]
            txs.append(Transmission(pl.LANDMARKS_TYPE, pl.encode_landmarks(t, share)))
            self._fit(t, r)
            self.last_fit_t = t
        fresh = [e for src, e in self.neighbours.items() if t - e.t_s <= p.estimate_max_age_s]
        had_estimate = self.est is not None
        self.est = consensus(self.own if self.own is not None and t - self.own.t_s <= p.estimate_max_age_s else None,
                             fresh, t, own_weight=0.8) or self.est
        ell = None
        if self.est is not None:
            try:
                ell = self._estimate_ellipsoid(t)
            except ValueError:
                ell = None
        slot = None
        if ell is not None:
            sd, x_s, nrm = surface_frame(ell, r)
            slot = x_s + p.r_buffer_m * nrm  # eq. 14
        old_mode = self.mode
        at_slot = slot is not None and norm3(r - slot) < p.dock_slot_tol_m
        self.mode = next_mode(self.mode, detected, received, self.settled, at_slot)
        if self.mode != "search" and ell is None:
            self.mode = "search" if old_mode == "search" else self.mode
        entered = old_mode == "search" and self.mode != "search"
        if entered:
            self.chase_entry_t = t

        f_col = apf_force(obs.rel_position_m, p.k_r, p.r_h_m)
        if self.mode == "search" or ell is None:
            if t - self.rnd_t >= p.random_redraw_s:
                self.rnd_force, self.rnd_t = random_force(self.rng, p.random_alpha, p.f_thr_n), t
            force = bounce_force(r, p.search_box_m, p.f_thr_n) + self.rnd_force + f_col
            if s.surface_rel_m is not None:
                d = norm3(s.surface_rel_m)
                force = force + buffer_force(d, -s.surface_rel_m / max(d, 1e-9), v, p.k_r_target,
                                             p.r_buffer_m, p.buffer_damping_nspm)
            scan = np.array([0.0, 0.0, np.radians(p.scan_rate_dps)]) if p.search_attitude == "scan" else None
            torque = rate_damping_torque(s.omega_body_radps, self.inertia, self.k_w, p.torque_max_nm, scan)
        else:
            forced = entered or not had_estimate
            if self._broadcast_due(t, r, v, forced, dt_s):
                e_max = p.approach_speed_mps * p.k_v / p.k_p if p.chase_law == "governed" else None
                self.held_force = chase_force(r, v, slot, self.est.velocity_mps, p.k_p, p.k_v, e_max)
                self.r_k, self.v_k, self.t_k = r.copy(), v.copy(), t
                msg = pl.StateMsg(t, self.mode, r, v, self.est.t_s, self.est.centre_m, self.est.velocity_mps,
                                  self.est.shape)
                txs.append(Transmission(pl.STATE_TYPE, pl.encode_state(msg)))
                self.broadcasts += 1
            force = self.held_force + f_col + buffer_force(sd, nrm, v - self.est.velocity_mps, p.k_r_target,
                                                           p.r_buffer_m, p.buffer_damping_nspm)
            q_d = desired_attitude(r, ell.centre_m)
            torque = pointing_torque(s.q_body_to_lvlh, s.omega_body_radps, q_d, self.inertia,
                                     self.k_q, self.k_w, p.torque_max_nm)
        force = saturate_norm(force, p.force_max_n)
        extra = {} if ell is None else {  # what the agent believes, for the report (Figs. 7, 12)
            "p000_axes_est_m": np.sort(ell.semi_axes_m), "p000_centre_est_m": ell.centre_m,
            "p000_surface_est_m": np.array([sd])}
        return Command(accel_mps2=force / p.mass_kg, mode=self.mode, transmissions=txs, torque_nm=torque,
                       extra=extra)


@register("p000-capture")
def make_capture(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> CaptureController:
    return CaptureController(sc_id, orbit, CaptureParams.from_dict(params))
