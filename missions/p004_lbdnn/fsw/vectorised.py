"""Paper 004's servicer laws over arrays of N servicers at once (issue 29: the batch path).

The same equations as lbdnn.py, observer.py, rho_filter.py, adaptation.py and control_law.py
(eqs. 2-3, 25-28), written for a leading axis of N servicers with every sum spelled out as an
elementwise product summed along a fixed axis (`np.add.reduce`, what `.sum` calls) (no BLAS call, whose blocking may depend on N): a
servicer's numbers do not depend on how many others share the call, so `LbdnnServicer.step`
(N = 1) and `LbdnnServicer.step_batch` (N = 6) give the same bits (tests/test_batch_missions.py).

State x (N, 9 + p): (eta_hat, zeta_hat, nu, theta_hat) per row, as controller.py `_held`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.missions.p004_lbdnn.fsw.lbdnn import LAYER_SIZES, n_params, sigmoid
from swarmhil.missions.p004_lbdnn.contract import Gains


@dataclass(frozen=True)
class Law:
    """What the N servicers of one call share (a batch groups servicers by it)."""

    gains: Gains
    use_network: bool
    theta_bar: float
    proj_epsilon: float
    rk4_substeps: int


def unpack(theta: np.ndarray, sizes: tuple[int, ...] = LAYER_SIZES) -> list[np.ndarray]:
    """theta (N, p) -> [V_1, ..., V_{k+1}], each (N, L_j + 1, L_{j+1}) (column-major vec blocks, §2.2)."""
    mats, at, n = [], 0, theta.shape[0]
    for a, b in zip(sizes[:-1], sizes[1:]):
        w = (a + 1) * b
        mats.append(theta[:, at:at + w].reshape(n, b, a + 1).transpose(0, 2, 1))
        at += w
    return mats


def _with_bias(x: np.ndarray) -> np.ndarray:
    out = np.empty((x.shape[0], x.shape[1] + 1))
    out[:, :-1], out[:, -1] = x, 1.0
    return out


def forward(kappa: np.ndarray, theta: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Phi(kappa, theta) (N, 3) by eq. 2 with the tanh output of §6, and, if asked, grad_theta Phi
    (N, 3, p) by eq. 3 times diag(1 - Phi^2) (lbdnn.py `forward`, `jacobian`)."""
    mats = unpack(theta)
    x = _with_bias(kappa)
    pre, inputs, sig = [], [], []
    for j, v in enumerate(mats):
        inputs.append(x)
        phi_j = np.add.reduce(x[:, :, None] * v, axis=1)  # varphi_j = V_{j+1}^T varrho_j^T
        pre.append(phi_j)
        if j < len(mats) - 1:
            sig.append(sigmoid(phi_j))
            x = _with_bias(phi_j * sig[-1])  # swish, then the bias 1
    out = np.tanh(pre[-1])
    if not jacobian:
        return out, None
    n, n_out = out.shape
    back = np.zeros((n, n_out, n_out))
    idx = np.arange(n_out)
    back[:, idx, idx] = 1.0 - out**2  # d Phi / d varphi_k
    jac = np.empty((n, n_out, n_params()))
    end = jac.shape[2]
    for j in range(len(mats) - 1, -1, -1):
        a = inputs[j]
        width = back.shape[2] * a.shape[1]
        jac[:, :, end - width:end] = (back[:, :, :, None] * a[:, None, None, :]).reshape(n, n_out, width)
        end -= width
        if j > 0:
            s = sig[j - 1]
            back = (np.add.reduce(back[:, :, None, :] * mats[j][:, None, :-1, :], axis=3)
                    * (s + pre[j - 1] * s * (1.0 - s))[:, None, :])  # times swish'
    return out, jac


def derivative(x: np.ndarray, eta: np.ndarray, coupling: np.ndarray, theta_nb: np.ndarray, n_nb: np.ndarray,
               law: Law) -> np.ndarray:
    """d/dt (eta_hat, zeta_hat, nu, theta_hat) of N servicers (eqs. 25, 26, 28). theta_nb (N, M, p):
    each one's neighbours' weights, rows past its n_nb (N,) neighbours zero."""
    g = law.gains
    eta_hat, zeta_hat, nu, theta = x[:, 0:3], x[:, 3:6], x[:, 6:9], x[:, 9:]
    eta_tilde = eta - eta_hat
    rho_i = -(g.k3 + g.k4) * eta_tilde + nu
    dx = np.empty_like(x)
    dx[:, 0:3] = zeta_hat
    dx[:, 3:6] = coupling - (g.k3**2 - 2.0) * eta_tilde - (2.0 * g.k3 + g.k4 + g.k5) * rho_i
    dx[:, 6:9] = (1.0 - g.k3**2 - g.k3 * g.k4) * eta_tilde - (g.k3 + g.k4 + g.k5) * rho_i
    if not law.use_network:
        dx[:, 9:] = 0.0
        return dx
    _out, jac = forward(np.concatenate([eta, zeta_hat], axis=1), theta, jacobian=True)
    assert jac is not None
    consensus = (1 + n_nb)[:, None] * theta - theta_nb.sum(axis=1)
    grad = np.add.reduce(jac * (zeta_hat + g.k1 * eta)[:, :, None], axis=1)  # grad Phi^T (zeta_hat + k1 eta)
    direction = g.gamma * (grad - g.k6 * consensus)
    # smooth projection onto ||theta|| <= theta_bar (adaptation.py `projection`)
    tt = np.add.reduce(theta * theta, axis=1)
    p = tt - law.theta_bar**2
    outward = np.add.reduce(theta * direction, axis=1)
    c = np.minimum(1.0, p / (law.proj_epsilon**2 + 2.0 * law.proj_epsilon * law.theta_bar))
    act = (p > 0.0) & (outward > 0.0)
    if not act.any():  # inside the ball, or pointing inwards: the direction unchanged
        dx[:, 9:] = direction
        return dx
    dx[:, 9:] = np.where(act[:, None], direction - (c * outward / np.where(act, tt, 1.0))[:, None] * theta, direction)
    return dx


def clip_to_ball(theta: np.ndarray, radius: float) -> np.ndarray:
    """Each row clipped radially to ||theta|| <= radius (adaptation.py `clip_to_ball`)."""
    norm = np.sqrt((theta * theta).sum(axis=1))
    over = norm > radius
    if not over.any():
        return theta
    return np.where(over[:, None], theta * (radius / np.where(over, norm, radius))[:, None], theta)


def propagate(x: np.ndarray, dt: float, eta: np.ndarray, coupling: np.ndarray, theta_nb: np.ndarray,
              n_nb: np.ndarray, law: Law) -> np.ndarray:
    """RK4 of the internal states over one hold interval (controller.py `_propagate_all`: what `_propagate` did per servicer)."""
    h = dt / law.rk4_substeps
    radius = law.theta_bar + law.proj_epsilon
    for _ in range(law.rk4_substeps):
        k1 = derivative(x, eta, coupling, theta_nb, n_nb, law)
        k2 = derivative(x + 0.5 * h * k1, eta, coupling, theta_nb, n_nb, law)
        k3 = derivative(x + 0.5 * h * k2, eta, coupling, theta_nb, n_nb, law)
        k4 = derivative(x + h * k3, eta, coupling, theta_nb, n_nb, law)
        x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        x[:, 9:] = clip_to_ball(x[:, 9:], radius)
    return x
