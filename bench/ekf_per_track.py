"""The camera navigation filter as it was before issue 16: one track (and one model) at a time.

`PerTrackEkf` overrides the three filter steps of agent.nav.ekf.EkfNavigator, which now run over
all tracks at once, with the per-track loops they replaced (2-D products per track and model,
`predict` and `noise_cov` per track and blob). Not flight software: the reference of
tests/test_nav_ekf_batched.py (bit-for-bit equality) and of bench/bench_ekf_ab.py (speed)."""
from __future__ import annotations

import numpy as np

from swarmhil.agent.nav import EkfNavigator
from swarmhil.agent.nav.measure import noise_cov, predict


class PerTrackEkf(EkfNavigator):
    """The filter steps as they were before issue 16: one track (and one model) at a time."""

    def _predict(self, dt, u0, own_accel):
        if dt <= 0.0:
            return
        phi, qs, shift, pi = self._predict_terms(dt, u0, own_accel)
        for tr in self.tracks:
            c = pi.T @ tr.mu
            w = pi * tr.mu[:, None] / np.maximum(c[None, :], 1e-300)
            x0 = w.T @ tr.xm
            d = tr.xm[:, None, :] - x0[None, :, :]
            p0 = np.einsum("ij,ikl->jkl", w, tr.pm) + np.einsum("ij,ijk,ijl->jkl", w, d, d)
            tr.xm = x0 @ phi.T - shift
            pm = phi @ p0 @ phi.T + qs
            tr.pm = 0.5 * (pm + pm.transpose(0, 2, 1))
            tr.mu = c
            tr.combine()

    def _innovations(self, t_cam, blobs):
        zs = np.stack((blobs.centroid_px[:, 0], blobs.centroid_px[:, 1], np.sqrt(np.maximum(blobs.area_px, 1e-12))), axis=1)
        t, m = len(self.tracks), len(blobs)
        hs, hph, depth = np.empty((t, 3)), np.empty((t, 3, 3)), np.empty(t)
        s = np.empty((t, m, 3, 3))
        for i, tr in enumerate(self.tracks):
            hs[i], jac, p = predict(self.model, tr.x, 0.0, self.n, t_cam)
            depth[i] = p[2]
            hph[i] = jac @ tr.p @ jac.T
            for j in range(m):
                s[i, j] = hph[i] + noise_cov(self.model, depth[i], blobs.area_px[j], blobs.area_sigma_px[j])
        return zs, hph, depth, zs[None, :, :] - hs[:, None, :], s

    def _update(self, rows, z, r, t_cam):
        for k, i in enumerate(rows):
            tr = self.tracks[i]
            loglik = np.zeros(len(tr.mu))
            for m in range(len(tr.mu)):
                h, jac, _ = predict(self.model, tr.xm[m], 0.0, self.n, t_cam)
                sm = jac @ tr.pm[m] @ jac.T + r[k]
                nu = z[k] - h
                sinv = np.linalg.inv(sm)
                gain = tr.pm[m] @ jac.T @ sinv
                ikh = np.eye(6) - gain @ jac
                tr.xm[m] = tr.xm[m] + gain @ nu
                pm = ikh @ tr.pm[m] @ ikh.T + gain @ r[k] @ gain.T
                tr.pm[m] = 0.5 * (pm + pm.T)
                loglik[m] = -0.5 * (nu @ sinv @ nu + np.linalg.slogdet(2.0 * np.pi * sm)[1])
            if len(tr.mu) > 1:
                w = np.log(np.maximum(tr.mu, 1e-300)) + loglik
                w = np.exp(w - w.max())
                tr.mu = w / w.sum()
            tr.combine()
