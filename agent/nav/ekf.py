"""Extended Kalman filter on the relative ROE of each tracked neighbour (issue 4).

State x = roe_m of the neighbour relative to the observer (k minus j), metres, with covariance P.
Dynamics (paper 002 Eq. 2, Keplerian, agent.roe): x' = A x + a B(u) (a_k - a_j). Over a frame
interval dt with the observer's own acceleration a_j held (ZOH) and the neighbour's a_k unknown
(white, sigma_acc per axis):
    x+ = Phi x - Gamma a_j,   P+ = Phi P Phi^T + Gamma (sigma_acc^2 I) Gamma^T,
    Phi = I + A dt (A nilpotent),  Gamma = Phi(dt/2) a B(u_mid) dt (midpoint rule, O((n dt)^2)).
Measurement per blob: (u, v, sqrt(area)) through the pinhole and the area model of
agent.nav.measure; noise from the blob's photometric sigma and the camera model.
Why an EKF and not a UKF: the measurement is smooth and nearly linear over the covariance of a
converged track (sub-pixel, a few per cent in range); the Jacobian is cheap and closed-form.

Manoeuvring neighbours (interacting multiple model, Bar-Shalom, Li & Kirubarajan 2001, "Estimation
with Applications to Tracking and Navigation", sec. 11.6): the neighbour's unknown control is the
process noise, and its level changes by orders of magnitude over a run (paper 002's law: ~1e-5 m/s^2
while the swarm forms, ~1e-7 once it has settled, the ideal 24 h run). One white level cannot fit
both: set for the transient it keeps ~1 m of a*da error forever (the settled relative state is then
known no better than the transient one); set for the settled swarm the filter is inconsistent
while the neighbour manoeuvres, its gate rejects the neighbour's blob and the track is lost. With
`manoeuvre_accel_sigma_mps2` > 0 each track runs two such filters, "quiet" (accel_sigma_mps2) and
"manoeuvring", mixed every frame by the IMM with a Markov switch whose mean sojourn times are
`quiet_sojourn_s` and `manoeuvre_sojourn_s`; the mode probabilities follow the innovations'
likelihoods. Association, gating and the output use the moment-matched mixture (mean and
covariance of the two). With manoeuvre_accel_sigma_mps2 = 0 (the default) it is the single EKF above.

Tracks: an unassigned blob starts a tentative track (position from bearing and the area model,
velocity prior N(0, sigma_v^2 I)); association is global nearest neighbour on the Mahalanobis
distance of the innovation, gated at chi^2_3(99.9 %) = 16.27, the pairs chosen by likelihood
(`assign_likelihood`: Mahalanobis distance plus ln det S); a track is confirmed after
`confirm_hits` updates; deleted after `max_misses` consecutive misses (a tentative one after one),
or when its prediction leaves the field of view or range by a margin. Out of view is not gone: with
`max_coast_s` > 0, a confirmed track whose prediction is outside the field of view or beyond the
detection range is kept (not output) for up to max_coast_s after its last blob instead, and takes
the blob back through the same gate when the relative orbit brings the neighbour into view again
(the ROE hardly change meanwhile, so the converged estimate is kept instead of restarting from a
0.2 m/s velocity prior); predicted in view and not seen for max_misses frames, it is deleted.
Output: confirmed tracks with at most `output_max_misses` consecutive misses (default max_misses).
With output_max_misses = 0 only the tracks a blob updated in this frame are output: the controller
acts on the neighbours the camera sees now, as with ideal sensing, and a track that coasts while a
new track has started on the same neighbour (its blob fell outside the old track's gate) is not
handed over twice.

Implementation (issue 16): each frame's predict with the IMM mixing, the innovations of every
(track, blob) pair and the update of every matched track run over the track axis at once (means
(T, M, 6), covariances (T, M, 6, 6)), each stacked product the same 2-D product per track and
model that the per-track filter computed: the estimates are bit-identical to it
(tests/test_nav_ekf_batched.py keeps that filter as the reference).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.agent.blob.blobs import Blobs
from swarmhil.agent.camera.model import R_LVLH_FROM_CAM, Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.agent.nav.associate import assign
from swarmhil.agent.nav.base import Track, guarded, update_together
from swarmhil.agent.nav.measure import (
    MeasurementModel,
    camera_position_matrix,
    noise_cov,
    noise_cov_many,
    noise_cov_pairs,
    predict_many,
)
from swarmhil.agent.roe import input_matrix, lvlh_to_roe, roe_to_lvlh, state_matrix


@dataclass(frozen=True)
class EkfConfig:
    accel_sigma_mps2: float = 1e-6
    init_velocity_sigma_mps: float = 0.2
    init_range_rel_sigma: float = 0.05
    gate_chi2: float = 16.27
    confirm_hits: int = 3
    max_misses: int = 5
    output_max_misses: int = -1  # output confirmed tracks with at most this many misses; -1: max_misses (docstring)
    fov_margin: float = 1.2  # delete a coasting track predicted beyond margin * half FOV
    range_margin: float = 1.5  # ... or beyond margin * the camera's max range
    max_coast_s: float = 0.0  # > 0: a confirmed track predicted out of view coasts this long (docstring)
    manoeuvre_accel_sigma_mps2: float = 0.0  # > 0: IMM with a second, manoeuvring model (docstring)
    quiet_sojourn_s: float = 5677.0  # mean time in each IMM mode (Markov switch); default one orbit
    manoeuvre_sojourn_s: float = 5677.0

    def sigmas_mps2(self) -> list[float]:
        """Process-noise levels of the models: [quiet] or [quiet, manoeuvring]."""
        if self.manoeuvre_accel_sigma_mps2 > 0.0:
            return [self.accel_sigma_mps2, self.manoeuvre_accel_sigma_mps2]
        return [self.accel_sigma_mps2]

    def switch_matrix(self, dt_s: float) -> np.ndarray:
        """(M, M) Markov mode transition over dt: pi[i, j] = P(mode j now | mode i before)."""
        if self.manoeuvre_accel_sigma_mps2 <= 0.0:
            return np.ones((1, 1))
        p01 = 1.0 - np.exp(-dt_s / self.quiet_sojourn_s)
        p10 = 1.0 - np.exp(-dt_s / self.manoeuvre_sojourn_s)
        return np.array([[1.0 - p01, p01], [p10, 1.0 - p10]])

    def stationary_modes(self) -> np.ndarray:
        if self.manoeuvre_accel_sigma_mps2 <= 0.0:
            return np.ones(1)
        w = np.array([self.quiet_sojourn_s, self.manoeuvre_sojourn_s])
        return w / w.sum()


@dataclass
class _EkfTrack:
    track_id: str
    x: np.ndarray  # (6,) mixture mean (the estimate)
    p: np.ndarray  # (6, 6) mixture covariance
    xm: np.ndarray  # (M, 6) per-model means
    pm: np.ndarray  # (M, 6, 6) per-model covariances
    mu: np.ndarray  # (M,) model probabilities
    age: int = 0
    hits: int = 1
    misses: int = 0
    blob_index: int = -1
    last_hit_t_s: float = 0.0

    def combine(self) -> None:
        """Moment-matched mixture of the models -> x, p."""
        self.x = self.mu @ self.xm
        d = self.xm - self.x
        self.p = np.einsum("m,mij->ij", self.mu, self.pm) + np.einsum("m,mi,mj->ij", self.mu, d, d)


def assign_likelihood(d2: np.ndarray, logdet_s: np.ndarray, gate_chi2: float) -> list[tuple[int, int]]:
    """Track-blob pairs inside the gate (d2 <= gate_chi2) that maximise the summed log-likelihood,
    i.e. minimise sum(d2 + ln det S) = -2 ln N(nu; 0, S) + const (Blackman & Popoli 1999, "Design
    and Analysis of Modern Tracking Systems", sec. 6.5). On d2 alone an uncertain track always
    looks nearer: a new tentative track on the same spacecraft would take the blob from the
    converged one frame after frame, until the converged track died of misses."""
    ok = d2 <= gate_chi2
    if not ok.any():
        return []
    cost = d2 + logdet_s
    cost = np.where(ok, cost - cost[ok].min(), np.inf)
    return assign(cost, float(cost[ok].max()))


MIN_DEPTH_M = 1.0  # a track predicted nearer than this in front of the camera (or behind it) is not associated


def gated_distances(nu: np.ndarray, s: np.ndarray, depth_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared Mahalanobis distances d2 (T, M) = nu' S^-1 nu and ln det S for every (track, blob).

    A track predicted behind the camera or nearer than MIN_DEPTH_M has no valid projection (the
    pinhole Jacobian goes as 1/z): its row is +inf, as is any (track, blob) whose S is singular or
    non-finite; so is the row of a track with any non-finite S or innovation. Such tracks coast on
    their prediction; none raises (a coasting track that drifted behind the camera once made
    np.linalg.solve raise and stopped an agent's step). `pair_distances` over the (T * M) pairs."""
    t, m = nu.shape[:2]
    ok = (depth_m > MIN_DEPTH_M) & np.isfinite(s).all(axis=(1, 2, 3)) & np.isfinite(nu).all(axis=(1, 2))
    d2, logdet = pair_distances(nu.reshape(t * m, 3), s.reshape(t * m, 3, 3), np.repeat(ok, m))
    return d2.reshape(t, m), logdet.reshape(t, m)


def pair_distances(nu: np.ndarray, s: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d2 = nu' S^-1 nu (P,) and ln det S (P,) of P pairs nu (P, 3), S (P, 3, 3); +inf and 0 where
    not `ok` (P,) or S is not positive definite by its determinant's sign. One LAPACK solve and one
    slogdet per pair whatever the pairs around it (the same values for a pair alone or among many)."""
    d2 = np.full(len(nu), np.inf)
    logdet = np.zeros(len(nu))
    if not ok.any():
        return d2, logdet
    if ok.all():  # the usual frame: no masking copies (the same solve per pair)
        sign, ld = np.linalg.slogdet(s)
        if (sign > 0).all():
            return np.einsum("pi,pi->p", nu, np.linalg.solve(s, nu[..., None])[..., 0]), ld
    sign, ld = np.linalg.slogdet(s[ok])
    good = sign > 0
    sol = np.zeros_like(nu[ok])
    if good.any():
        sol[good] = np.linalg.solve(s[ok][good], nu[ok][good][..., None])[..., 0]
    d2[ok] = np.where(good, np.einsum("pi,pi->p", nu[ok], sol), np.inf)
    logdet[ok] = np.where(good, ld, 0.0)
    return d2, logdet


def transition(n_radps: float, dt_s: float) -> np.ndarray:
    return np.eye(6) + state_matrix(n_radps) * dt_s


def input_gamma(u0_rad: float, a_m: float, n_radps: float, dt_s: float) -> np.ndarray:
    """Gamma (6, 3): metres of roe per m/s^2 held over dt (midpoint rule)."""
    um = u0_rad + 0.5 * n_radps * dt_s
    return transition(n_radps, 0.5 * dt_s) @ (a_m * input_matrix(um, a_m, n_radps)) * dt_s


def lvlh_to_roe_matrices(u_rad: float, n_radps: float) -> tuple[np.ndarray, np.ndarray]:
    """(Mp, Mv), each (6, 3): roe_m = Mp @ pos + Mv @ vel (the linear map M of paper 002 sec. 5)."""
    z = np.zeros((3, 3))
    mp = lvlh_to_roe(np.eye(3), z, u_rad, n_radps).T
    mv = lvlh_to_roe(z, np.eye(3), u_rad, n_radps).T
    return mp, mv


def imm_predict(xm: np.ndarray, pm: np.ndarray, mu: np.ndarray, phi: np.ndarray, qs: np.ndarray, shift: np.ndarray,
                pi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IMM interaction (mixing) then each model's prediction x+ = Phi x0 - Gamma a_j, P+ = Phi P0 Phi^T + Q
    (module docstring; Bar-Shalom et al. 2001 sec. 11.6.6) of T tracks stacked: per-model means
    xm (T, M, 6), covariances pm (T, M, 6, 6), mode probabilities mu (T, M); `shift` Gamma a_j is
    (6,) for all or (T, 1, 6) per track. Returns the predicted xm, pm and mode probabilities
    c = pi^T mu. Every product is the same 2-D product per track whatever T (tests/test_nav_ekf_batched.py)."""
    c = np.matmul(pi.T, mu[:, :, None])[:, :, 0]  # predicted mode probabilities (T, M)
    w = pi * mu[:, :, None] / np.maximum(c[:, None, :], 1e-300)  # w[t, i, j] = P(i before | j now)
    x0 = np.matmul(w.transpose(0, 2, 1), xm)
    d = xm[:, :, None, :] - x0[:, None, :, :]  # (t, i, j, 6)
    p0 = np.einsum("tij,tikl->tjkl", w, pm) + np.einsum("tij,tijk,tijl->tjkl", w, d, d)
    xm = x0 @ phi.T - shift
    pm = phi @ p0 @ phi.T + qs
    return xm, 0.5 * (pm + pm.transpose(0, 1, 3, 2)), c


def mixture(xm: np.ndarray, pm: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moment-matched mixture of each track's models: x = sum_m mu_m x_m (T, 6),
    P = sum_m mu_m (P_m + (x_m - x)(x_m - x)^T) (T, 6, 6)."""
    x = np.matmul(mu[:, None, :], xm)[:, 0]
    d = xm - x[:, None, :]
    return x, np.einsum("tm,tmij->tij", mu, pm) + np.einsum("tm,tmi,tmj->tij", mu, d, d)


def imm_update(model: MeasurementModel, xm: np.ndarray, pm: np.ndarray, mu: np.ndarray, z: np.ndarray, r: np.ndarray,
               t_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each model's EKF update (Joseph form) of K tracks xm (K, M, 6), pm (K, M, 6, 6) with
    measurements z (K, 3) and noises R (K, 3, 3); mode probabilities from the innovation
    likelihoods N(nu; 0, S) (IMM). Returns (xm, pm, mu) of the tracks whose S is regular in every
    model, and ok (K,) marking them (a track with a singular S keeps its prediction: a fault)."""
    k_, m_ = mu.shape
    h, jac, _ = predict_many(model, xm.reshape(k_ * m_, 6), t_cam)
    h, jac = h.reshape(k_, m_, 3), jac.reshape(k_, m_, 3, 6)
    jt = jac.transpose(0, 1, 3, 2)
    r = r[:, None]
    sm = jac @ pm @ jt + r
    nu = z[:, None, :] - h
    ok = np.ones(k_, bool)
    try:
        sinv = np.linalg.inv(sm)
    except np.linalg.LinAlgError:  # one singular S: invert one by one, skip the tracks concerned
        sinv = np.zeros_like(sm)
        for k in range(k_):
            try:
                sinv[k] = np.linalg.inv(sm[k])
            except np.linalg.LinAlgError:
                ok[k] = False
        if not ok.any():
            return xm[ok], pm[ok], mu[ok], ok
        xm, pm, mu, jac, jt, r, sm, nu, sinv = (a[ok] for a in (xm, pm, mu, jac, jt, r, sm, nu, sinv))
    gain = pm @ jt @ sinv
    ikh = np.eye(6) - gain @ jac
    xm = xm + np.matmul(gain, nu[..., None])[..., 0]
    pm = ikh @ pm @ ikh.transpose(0, 1, 3, 2) + gain @ r @ gain.transpose(0, 1, 3, 2)
    pm = 0.5 * (pm + pm.transpose(0, 1, 3, 2))  # round-off: P spans ~1e-5 to ~1e5 m^2 while the velocity prior is forgotten
    if m_ > 1:
        maha = np.matmul(np.matmul(nu[..., None, :], sinv), nu[..., :, None])[..., 0, 0]
        loglik = -0.5 * (maha + np.linalg.slogdet(2.0 * np.pi * sm)[1])
        w = np.log(np.maximum(mu, 1e-300)) + loglik
        w = np.exp(w - w.max(axis=1, keepdims=True))
        mu = w / w.sum(axis=1, keepdims=True)
    return xm, pm, mu, ok


def measurements(blobs: Blobs) -> np.ndarray:
    """z = (u, v, sqrt(area)) (B, 3) of each blob."""
    return np.stack((blobs.centroid_px[:, 0], blobs.centroid_px[:, 1], np.sqrt(np.maximum(blobs.area_px, 1e-12))), axis=1)


_PREDICT_TERMS: dict[tuple, tuple[np.ndarray, ...]] = {}  # EkfNavigator._predict_terms's shared terms
_BATCH_KEYS: dict[tuple, int] = {}  # EkfNavigator.batch_key: one number per distinct setting of the filter


class EkfNavigator:
    name = "ekf"

    def __init__(self, camera: Camera, shape: SpacecraftShape, a_m: float, n_radps: float, config: EkfConfig | None = None, model: MeasurementModel | None = None) -> None:
        self.camera = camera
        self.model = model or MeasurementModel.for_shape(camera, shape)
        self.a_m, self.n = a_m, n_radps
        self.cfg = config or EkfConfig()
        self.tracks: list[_EkfTrack] = []
        self._t: float | None = None
        self._u: float | None = None
        self._next_id = 0
        self.faults = 0  # updates skipped (singular or non-finite S) + tracks dropped as non-finite
        mdl = self.model  # what `update_many` needs equal to step navigators together (all the arithmetic's inputs)
        key = (type(self), float(a_m).hex(), float(n_radps).hex(), self.cfg, camera, mdl.camera,
               tuple(float(a).hex() for a in mdl.areas_m2), mdl.extent_m, mdl.centroid_floor_px, mdl.area_rel_sigma)
        self.batch_key = _BATCH_KEYS.setdefault(key, len(_BATCH_KEYS))  # (a small int: compared every frame)

    # -- filter steps (issue 16: every track, model and matched pair at once; numpy over the
    #    track axis, each product the same 2-D product per track as the per-track filter had) ---
    def _stack(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-model means (T, M, 6), covariances (T, M, 6, 6) and mode probabilities (T, M)."""
        trs = self.tracks
        return np.stack([t.xm for t in trs]), np.stack([t.pm for t in trs]), np.stack([t.mu for t in trs])

    def _predict_terms(self, dt: float, u0: float, own_accel: np.ndarray | None):
        """Phi, the models' process noises Q (M, 6, 6), the own-thrust shift Gamma a_j and the
        Markov switch matrix over dt (module docstring)."""
        phi, gam, qs, pi = self._terms(dt, u0)
        shift = np.zeros(6) if own_accel is None else gam @ np.asarray(own_accel, dtype=float)
        return phi, qs, shift, pi

    def _terms(self, dt: float, u0: float) -> tuple[np.ndarray, ...]:
        """Phi, Gamma, Q and the switch matrix: they depend on (n, a, dt, u0) and the config only,
        remembered (read-only) for the last few, which the navigators of a batch run share (each
        computes the same values)."""
        key = (float(self.n).hex(), float(self.a_m).hex(), float(dt).hex(), float(u0).hex(), self.cfg)
        terms = _PREDICT_TERMS.get(key)
        if terms is None:
            phi = transition(self.n, dt)
            gam = input_gamma(u0, self.a_m, self.n, dt)
            gg = gam @ gam.T
            qs = np.array([s**2 * gg for s in self.cfg.sigmas_mps2()])
            pi = self.cfg.switch_matrix(dt)
            for a in (phi, gam, qs, pi):
                a.setflags(write=False)
            if len(_PREDICT_TERMS) >= 8:
                _PREDICT_TERMS.clear()
            terms = _PREDICT_TERMS[key] = (phi, gam, qs, pi)
        return terms

    def _predict(self, dt: float, u0: float, own_accel: np.ndarray | None) -> None:
        """IMM interaction (mixing) then each model's prediction, for all tracks at once; one model:
        the plain EKF step."""
        if dt <= 0.0 or not self.tracks:
            return
        phi, qs, shift, pi = self._predict_terms(dt, u0, own_accel)
        xm, pm, c = imm_predict(*self._stack(), phi, qs, shift, pi)
        self._store(range(len(self.tracks)), xm, pm, c)

    def _store(self, rows, xm: np.ndarray, pm: np.ndarray, mu: np.ndarray) -> None:
        """Write per-model states back to the tracks `rows` and form each one's mixture."""
        x, p = mixture(xm, pm, mu)
        for k, i in enumerate(rows):
            tr = self.tracks[i]
            tr.xm, tr.pm, tr.mu, tr.x, tr.p = xm[k], pm[k], mu[k], x[k], p[k]

    def _innovations(self, t_cam: np.ndarray, blobs: Blobs):
        """Per track: h, H, H P H^T and depth; per (track, blob): innovation nu (T, B, 3), S (T, B, 3, 3)."""
        zs = measurements(blobs)
        x = np.stack([tr.x for tr in self.tracks])
        p = np.stack([tr.p for tr in self.tracks])
        hs, jacs, pcam = predict_many(self.model, x, t_cam)
        depth = pcam[:, 2]
        nu = zs[None, :, :] - hs[:, None, :]
        hph = jacs @ p @ jacs.transpose(0, 2, 1)
        s = hph[:, None] + noise_cov_many(self.model, depth, blobs.area_px, blobs.area_sigma_px)
        return zs, hph, depth, nu, s

    def _update(self, rows: list[int], z: np.ndarray, r: np.ndarray, t_cam: np.ndarray) -> None:
        """`imm_update` of the tracks `rows` with measurements z (K, 3), noises R (K, 3, 3), then the
        mixture; a track whose S is singular in any model keeps its prediction (a fault)."""
        trs = [self.tracks[i] for i in rows]
        xm, pm, mu = np.stack([t.xm for t in trs]), np.stack([t.pm for t in trs]), np.stack([t.mu for t in trs])
        xm, pm, mu, ok = imm_update(self.model, xm, pm, mu, z, r, t_cam)
        self.faults += int((~ok).sum())
        if ok.any():
            self._store([i for i, good in zip(rows, ok.tolist()) if good], xm, pm, mu)

    def _new_track(self, u_rad: float, centroid: np.ndarray, area: float, area_sigma: float) -> _EkfTrack:
        cam, mdl, cfg = self.camera, self.model, self.cfg
        tx, ty = (centroid[0] - cam.cx) / cam.focal_px, (centroid[1] - cam.cy) / cam.focal_px
        ax, ay, az = mdl.areas_m2
        z = cam.focal_px * np.sqrt((az + ax * abs(tx) + ay * abs(ty)) / max(area, 1e-12))
        p_cam = z * np.array([tx, ty, 1.0])
        r = noise_cov(mdl, z, area, area_sigma)
        rel_z2 = (area_sigma / (2.0 * area)) ** 2 + mdl.area_rel_sigma**2 + cfg.init_range_rel_sigma**2
        jac = np.array([[z, 0.0, tx], [0.0, z, ty], [0.0, 0.0, 1.0]])
        p_cam_cov = jac @ np.diag([r[0, 0] / cam.focal_px**2, r[1, 1] / cam.focal_px**2, rel_z2 * z * z]) @ jac.T
        pos = R_LVLH_FROM_CAM @ p_cam
        pos_cov = R_LVLH_FROM_CAM @ p_cam_cov @ R_LVLH_FROM_CAM.T
        mp, mv = lvlh_to_roe_matrices(u_rad, self.n)
        x = mp @ pos
        p = mp @ pos_cov @ mp.T + cfg.init_velocity_sigma_mps**2 * mv @ mv.T
        mu = self.cfg.stationary_modes()
        tr = _EkfTrack(f"e{self._next_id}", x, p, np.tile(x, (len(mu), 1)), np.tile(p, (len(mu), 1, 1)), mu)
        self._next_id += 1
        return tr

    def _in_view(self, tr: _EkfTrack, t_cam: np.ndarray, fov_margin: float, range_margin: float) -> bool:
        """The track's predicted position lies within fov_margin * the half FOV and range_margin * the range."""
        p = t_cam @ tr.x  # camera-frame position, as in predict
        tan_x, tan_y = (np.tan(a) for a in self.camera.half_fov_rad)
        return bool(
            p[2] > 0
            and abs(p[0]) <= fov_margin * tan_x * p[2]
            and abs(p[1]) <= fov_margin * tan_y * p[2]
            and np.linalg.norm(p) <= range_margin * self.camera.max_range_m
        )

    def _alive(self, tr: _EkfTrack, t_s: float, t_cam: np.ndarray) -> bool:
        cfg = self.cfg
        if tr.misses == 0:
            return True
        if tr.hits < cfg.confirm_hits:
            return False
        if cfg.max_coast_s > 0.0 and not self._in_view(tr, t_cam, 1.0, 1.0):
            return t_s - tr.last_hit_t_s <= cfg.max_coast_s  # out of view, not gone: coast
        return tr.misses <= cfg.max_misses and self._in_view(tr, t_cam, cfg.fov_margin, cfg.range_margin)

    def _begin(self, t_s: float, u_rad: float) -> None:
        """The frame's clock, and every track one frame older with no blob yet."""
        self._t, self._u = t_s, u_rad
        for tr in self.tracks:
            tr.age += 1
            tr.blob_index = -1

    def _settle(self, t_s: float, u_rad: float, blobs: Blobs, pairs: list[tuple[int, int]], t_cam: np.ndarray,
                finite: list[bool] | None = None) -> list[_EkfTrack]:
        """After the update of the matched tracks: hits and misses, non-finite and dead tracks dropped,
        a tentative track started on every unmatched blob; returns the tracks to output (module
        docstring). `finite`: per track, are its x and P finite (computed here when not given)."""
        for i, j in pairs:
            tr = self.tracks[i]
            tr.hits += 1
            tr.misses = 0
            tr.last_hit_t_s = t_s
            tr.blob_index = j
        matched_t = {i for i, _ in pairs}
        for i, tr in enumerate(self.tracks):
            if i not in matched_t:
                tr.misses += 1
        if finite is None:
            finite = finite_tracks([tr.x for tr in self.tracks], [tr.p for tr in self.tracks])
        self.faults += finite.count(False)
        self.tracks = [tr for tr, ok in zip(self.tracks, finite) if ok and self._alive(tr, t_s, t_cam)]
        matched_b = {j for _, j in pairs}
        for j in range(len(blobs)):
            if j not in matched_b:
                tr = self._new_track(u_rad, blobs.centroid_px[j], float(blobs.area_px[j]), float(blobs.area_sigma_px[j]))
                tr.blob_index = j
                tr.last_hit_t_s = t_s
                self.tracks.append(tr)
        cfg = self.cfg
        out_misses = cfg.max_misses if cfg.output_max_misses < 0 else min(cfg.output_max_misses, cfg.max_misses)
        return [tr for tr in self.tracks if tr.hits >= cfg.confirm_hits and tr.misses <= out_misses]

    # -- the Navigator interface --------------------------------------------------------------
    def update(self, t_s: float, u_rad: float, blobs: Blobs, own_accel_mps2: np.ndarray | None = None) -> list[Track]:
        if self._t is not None:
            self._predict(t_s - self._t, self._u, own_accel_mps2)
        self._begin(t_s, u_rad)
        pairs: list[tuple[int, int]] = []
        t_cam = camera_position_matrix(u_rad, self.n)
        if self.tracks and len(blobs):
            zs, hph, depth, nu, s = self._innovations(t_cam, blobs)
            d2, logdet = gated_distances(nu, s, depth)
            pairs = assign_likelihood(d2, logdet, self.cfg.gate_chi2)
            if pairs:
                rows, cols = [i for i, _ in pairs], [j for _, j in pairs]
                self._update(rows, zs[cols], s[rows, cols] - hph[rows], t_cam)
        return tracks_out([self._settle(t_s, u_rad, blobs, pairs, t_cam)], u_rad, self.n)[0]


def finite_tracks(xs: list[np.ndarray], ps: list[np.ndarray]) -> list[bool]:
    """Per track: are all of its x (6,) and P (6, 6) finite."""
    if not xs:
        return []
    return (np.isfinite(np.stack(xs)).all(axis=1) & np.isfinite(np.stack(ps)).all(axis=(1, 2))).tolist()


def tracks_out(outs: list[list[_EkfTrack]], u_rad: float, n_radps: float) -> list[list[Track]]:
    """The output `Track`s of several navigators' output tracks: one ROE -> LVLH for all (elementwise:
    each row as for one)."""
    flat = [tr for out in outs for tr in out]
    if not flat:
        return [[] for _ in outs]
    pos, vel = roe_to_lvlh(np.stack([tr.x for tr in flat]), u_rad, n_radps)
    res, k = [], 0
    for out in outs:
        res.append([Track(tr.track_id, tr.x.copy(), pos[k + i], vel[k + i], tr.p.copy(), tr.age, tr.hits, tr.blob_index,
                          tr.pm[0].copy() if len(tr.pm) > 1 else None)
                    for i, tr in enumerate(out)])
        k += len(out)
    return res


def update_many(navs: list[EkfNavigator], t_s: float, u_rad: float, blobs: list[Blobs],
                own_accel_mps2: list[np.ndarray | None]) -> list[list[Track] | Exception]:
    """`update` of several navigators for one frame (navs[k] sees blobs[k] with its own acceleration
    own_accel_mps2[k]: the observers of a batch step), every observer's tracks stacked: one IMM
    prediction, one pass over the (track, blob) pairs of every observer (innovations, S, gating),
    the association per observer, one update of every matched track, one mixture. Each navigator
    ends in the state its own `update` gives, bit for bit: every product is the same 2-D product per
    track or pair as in `update` (`imm_predict`, `pair_distances`, `imm_update` over the rows of all
    observers; tests/test_nav_ekf_batched.py). Navigators of different settings or classes
    (`batch_key`) are updated one by one.

    Returns each navigator's tracks, or the exception its own `update` would have raised (then, as
    after that raise, its state is undefined: the caller resets it). Nothing is written before the
    arithmetic of every observer is done: if it raises, each navigator runs its own `update`."""
    return update_together(navs, t_s, u_rad, blobs, own_accel_mps2, _frame_arrays, _commit_frame)


@dataclass
class _FramePlan:
    """What `update_many` computed for one frame, before anything is written (rows: every track of
    every navigator, navigator by navigator, in their order)."""

    start: np.ndarray  # (N + 1,) first row of each navigator
    predicted: np.ndarray  # (G,) bool: the row was predicted
    xm: np.ndarray  # (G, M, 6) per-model means after the prediction
    pm: np.ndarray
    mu: np.ndarray
    x: np.ndarray  # (G, 6) mixture after the prediction (the track's own where not predicted)
    p: np.ndarray
    pairs: list[list[tuple[int, int]]]  # per navigator, its (track, blob) pairs
    upd_rows: np.ndarray  # (K,) rows updated (the ok ones of the matched)
    upd: tuple[np.ndarray, ...]  # their xm, pm, mu, x, p after the update
    bad: np.ndarray  # (N,) per navigator, matched tracks whose update was skipped (singular S)


def _frame_arrays(navs: list[EkfNavigator], t_s: float, u_rad: float, blobs: list[Blobs],
                  own_accel_mps2: list[np.ndarray | None]) -> _FramePlan:
    """The arithmetic of `update_many`: prediction, innovations, gating, association and update of
    every navigator's tracks; no navigator is changed."""
    counts = np.array([len(nav.tracks) for nav in navs], dtype=np.int64)
    start = np.concatenate(([0], np.cumsum(counts)))
    trs = [tr for nav in navs for tr in nav.tracks]
    g_ = len(trs)
    m_ = len(navs[0].cfg.sigmas_mps2())
    if g_ == 0:
        xm, pm, mu = np.zeros((0, m_, 6)), np.zeros((0, m_, 6, 6)), np.zeros((0, m_))
    else:
        xm, pm, mu = np.stack([t.xm for t in trs]), np.stack([t.pm for t in trs]), np.stack([t.mu for t in trs])
    predicted = np.zeros(g_, bool)
    # the prediction: the navigators that share Phi, Q and the switch matrix (a frame: all) together
    groups: dict[tuple[str, str], list[tuple[int, np.ndarray]]] = {}
    terms: dict[tuple[str, str], tuple[np.ndarray, ...]] = {}
    for k, nav in enumerate(navs):  # as `update`: predicted when the navigator has a clock, tracks and dt > 0
        if nav._t is None or not counts[k] or t_s - nav._t <= 0.0:
            continue
        key = (float(nav._t).hex(), float(nav._u).hex())  # (a frame: one) -> Phi, Gamma, Q, switch (exactly: -0.0 is not 0.0)
        if key not in terms:
            terms[key] = nav._terms(t_s - nav._t, nav._u)
        gam, acc = terms[key][1], own_accel_mps2[k]
        groups.setdefault(key, []).append((k, np.zeros(6) if acc is None else gam @ np.asarray(acc, dtype=float)))
    x = np.zeros((g_, 6))
    p = np.zeros((g_, 6, 6))
    for key, members in groups.items():
        phi, _, qs, pi = terms[key]
        if sum(int(counts[k]) for k, _ in members) == g_:  # (the usual frame: every row, no copies)
            rows = slice(None)
        else:
            rows = np.concatenate([np.arange(start[k], start[k + 1]) for k, _ in members])
        shift = np.repeat(np.stack([sh for _, sh in members]), [int(counts[k]) for k, _ in members], axis=0)[:, None, :]
        xm_p, pm_p, c = imm_predict(xm[rows], pm[rows], mu[rows], phi, qs, shift, pi)
        xm[rows], pm[rows], mu[rows] = xm_p, pm_p, c
        x[rows], p[rows] = mixture(xm_p, pm_p, c)
        predicted[rows] = True
    for g in np.flatnonzero(~predicted).tolist():
        x[g], p[g] = trs[g].x, trs[g].p
    # innovations of every observer's (track, blob) pairs
    t_cam = camera_position_matrix(u_rad, navs[0].n)
    model, cfg = navs[0].model, navs[0].cfg
    seen = [k for k, nav in enumerate(navs) if counts[k] and len(blobs[k])]
    pairs: list[list[tuple[int, int]]] = [[] for _ in navs]
    upd_g: list[int] = []
    upd_q: list[int] = []
    upd_b: list[int] = []
    if seen:
        tcount = counts[seen]
        nb = np.array([len(blobs[k]) for k in seen], dtype=np.int64)
        is_seen = np.zeros(len(navs), bool)
        is_seen[seen] = True
        trows = np.flatnonzero(np.repeat(is_seen, counts))  # the seen navigators' rows, in order
        bstart = np.concatenate(([0], np.cumsum(nb)))
        npairs = tcount * nb
        qstarts = np.concatenate(([0], np.cumsum(npairs)))
        cen = np.concatenate([blobs[k].centroid_px for k in seen])
        area = np.concatenate([blobs[k].area_px for k in seen])
        sig = np.concatenate([blobs[k].area_sigma_px for k in seen])
        zs = np.stack((cen[:, 0], cen[:, 1], np.sqrt(np.maximum(area, 1e-12))), axis=1)  # `measurements`
        hs, jacs, pcam = predict_many(model, x[trows], t_cam)
        depth = pcam[:, 2]
        hph = jacs @ p[trows] @ jacs.transpose(0, 2, 1)
        # pairs navigator by navigator, track-major: each track of navigator k with each of its blobs
        ti = np.repeat(np.arange(len(trows)), np.repeat(nb, tcount))
        owner = np.repeat(np.arange(len(seen)), npairs)
        bj = bstart[owner] + (np.arange(int(qstarts[-1])) - qstarts[owner]) % nb[owner]
        nu = zs[bj] - hs[ti]
        s = hph[ti] + noise_cov_pairs(model, depth[ti], area[bj], sig[bj])
        bad_pair = ~(np.isfinite(s).all(axis=(1, 2)) & np.isfinite(nu).all(axis=1))
        ok = (depth > MIN_DEPTH_M) & ~(np.bincount(ti, weights=bad_pair, minlength=len(trows)) > 0)
        d2, logdet = pair_distances(nu, s, ok[ti])
        for i, k in enumerate(seen):
            t_k, b_k, qstart = int(counts[k]), int(nb[i]), int(qstarts[i])
            seg = slice(qstart, qstart + t_k * b_k)
            pairs[k] = assign_likelihood(d2[seg].reshape(t_k, b_k), logdet[seg].reshape(t_k, b_k), cfg.gate_chi2)
            for a, b in pairs[k]:
                upd_g.append(int(start[k]) + a)
                upd_q.append(qstart + a * b_k + b)
                upd_b.append(int(bstart[i]) + b)
    bad = np.zeros(len(navs), dtype=np.int64)
    upd_rows = np.zeros(0, dtype=np.int64)
    upd: tuple[np.ndarray, ...] = ()
    if upd_g:
        g_idx = np.array(upd_g)
        # hph of the pair's track: its row among the seen navigators' rows (trows is increasing)
        r = s[upd_q] - hph[np.searchsorted(trows, g_idx)]
        xm_u, pm_u, mu_u, ok_u = imm_update(model, xm[g_idx], pm[g_idx], mu[g_idx], zs[upd_b], r, t_cam)
        owner = np.searchsorted(start, g_idx, side="right") - 1
        bad = np.bincount(owner[~ok_u], minlength=len(navs))
        upd_rows = g_idx[ok_u]
        if len(upd_rows):
            upd = (xm_u, pm_u, mu_u, *mixture(xm_u, pm_u, mu_u))
    return _FramePlan(start, predicted, xm, pm, mu, x, p, pairs, upd_rows, upd, bad)


def _commit_frame(navs: list[EkfNavigator], t_s: float, u_rad: float, blobs: list[Blobs],
                  plan: _FramePlan) -> list[list[Track] | Exception]:
    """Write `_frame_arrays`' results into the navigators, in the order of their own `update`, and
    finish each one's frame (`_settle`)."""
    trs = [tr for nav in navs for tr in nav.tracks]
    for g in np.flatnonzero(plan.predicted).tolist():
        tr = trs[g]
        tr.xm, tr.pm, tr.mu, tr.x, tr.p = plan.xm[g], plan.pm[g], plan.mu[g], plan.x[g], plan.p[g]
    for nav in navs:
        nav._begin(t_s, u_rad)
    x, p = plan.x, plan.p
    if len(plan.upd_rows):
        xm_u, pm_u, mu_u, x_u, p_u = plan.upd
        for k, g in enumerate(plan.upd_rows.tolist()):
            tr = trs[g]
            tr.xm, tr.pm, tr.mu, tr.x, tr.p = xm_u[k], pm_u[k], mu_u[k], x_u[k], p_u[k]
        x, p = x.copy(), p.copy()
        x[plan.upd_rows], p[plan.upd_rows] = x_u, p_u
    finite = (np.isfinite(x).all(axis=1) & np.isfinite(p).all(axis=(1, 2))).tolist()
    t_cam = camera_position_matrix(u_rad, navs[0].n)
    outs: list[list[_EkfTrack] | Exception] = []
    for k, nav in enumerate(navs):
        nav.faults += int(plan.bad[k])
        a, b = int(plan.start[k]), int(plan.start[k + 1])
        outs.append(guarded(nav._settle, t_s, u_rad, blobs[k], plan.pairs[k], t_cam, finite[a:b]))
    good = [o for o in outs if not isinstance(o, Exception)]
    tracks = iter(tracks_out(good, u_rad, navs[0].n))  # type: ignore[arg-type]
    return [o if isinstance(o, Exception) else next(tracks) for o in outs]
