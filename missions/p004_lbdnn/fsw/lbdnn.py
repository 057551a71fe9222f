"""The Lyapunov-based deep neural network of paper 004: forward pass and Jacobian in the weights.

Architecture (paper 004 §6): input kappa = (eta, zeta_hat) in R^6, four hidden layers of four
Swish neurons, output in R^3 through tanh; every layer carries an augmented bias row (eq. 2), so
V_{j+1} is (L_j + 1) x L_{j+1} and p = sum_j (L_j + 1) L_{j+1} = 28 + 3*20 + 15 = 103.

theta = [vec(V_1); ...; vec(V_5)] with vec() column-major (paper §2), i.e. the entry V[l, m]
of a layer with L^a rows sits at offset l + m * L^a of that layer's block.

The output layer: eq. 2 is written linear, §6 says tanh (NOTES-004 "Output layer"); here
Phi = tanh(V_5^T phi_4(...)), so the Jacobian of eq. 3 gains the factor diag(1 - Phi^2).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

LAYER_SIZES: tuple[int, ...] = (6, 4, 4, 4, 4, 3)
"""L_0 ... L_{k+1} of paper 004 §6 (k = 4 hidden layers of 4 neurons)."""


@dataclass(frozen=True)
class Forward:
    """What the forward pass keeps for the Jacobian: pre-activations and layer inputs."""

    output: np.ndarray  # Phi(kappa, theta), (L_{k+1},)
    pre: list[np.ndarray]  # varphi_j, j = 0..k (pre-activation of layer j+1)
    inputs: list[np.ndarray]  # varrho_j^T: kappa_a for j = 0, phi_j(varphi_{j-1}) for j >= 1
    mats: list[np.ndarray]  # V_1 ... V_{k+1} the pass used


@lru_cache(maxsize=8)  # a few times per servicer and step (issue 29)
def n_params(sizes: tuple[int, ...] = LAYER_SIZES) -> int:
    """p = sum_{j=0}^{k} L_j^a L_{j+1} (paper 004 §2.2, below eq. 2)."""
    return sum((a + 1) * b for a, b in zip(sizes[:-1], sizes[1:]))


def unpack(theta: np.ndarray, sizes: tuple[int, ...] = LAYER_SIZES) -> list[np.ndarray]:
    """theta -> [V_1, ..., V_{k+1}], each (L_j + 1, L_{j+1}), from column-major vec() blocks."""
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (n_params(sizes),):
        raise ValueError(f"theta has shape {theta.shape}, expected ({n_params(sizes)},)")
    mats, at = [], 0
    for a, b in zip(sizes[:-1], sizes[1:]):
        n = (a + 1) * b
        mats.append(theta[at:at + n].reshape((a + 1, b), order="F"))
        at += n
    return mats


def pack(mats: list[np.ndarray]) -> np.ndarray:
    """[V_1, ..., V_{k+1}] -> theta (column-major vec of each, concatenated; paper 004 §2.2)."""
    return np.concatenate([np.asarray(v, dtype=float).ravel(order="F") for v in mats])


def sigmoid(x: np.ndarray) -> np.ndarray:
    """Logistic function, written with tanh so that kilometre-sized inputs do not overflow."""
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def swish(x: np.ndarray) -> np.ndarray:
    """Swish activation x * sigmoid(x) (paper 004 §6, ref. [38], beta = 1)."""
    return x * sigmoid(x)


def swish_prime(x: np.ndarray) -> np.ndarray:
    """d swish / dx = s + x s (1 - s), s = sigmoid(x)."""
    s = sigmoid(x)
    return s + x * s * (1.0 - s)


def forward(kappa: np.ndarray, theta: np.ndarray, sizes: tuple[int, ...] = LAYER_SIZES) -> Forward:
    """Phi(kappa, theta) by the recursion of paper 004 eq. 2, with the tanh output of §6."""
    kappa = np.asarray(kappa, dtype=float)
    if kappa.shape != (sizes[0],):
        raise ValueError(f"kappa has shape {kappa.shape}, expected ({sizes[0]},)")
    mats = unpack(theta, sizes)
    x = np.empty(sizes[0] + 1)
    x[:-1], x[-1] = kappa, 1.0  # kappa_a
    pre, inputs = [], []
    for j, v in enumerate(mats):
        inputs.append(x)
        phi_j = x @ v  # varphi_j = V_{j+1}^T varrho_j^T
        pre.append(phi_j)
        if j < len(mats) - 1:
            x = np.empty(phi_j.size + 1)
            x[:-1], x[-1] = swish(phi_j), 1.0  # phi_{j+1}(varphi_j) with the bias 1 appended
    return Forward(output=np.tanh(pre[-1]), pre=pre, inputs=inputs, mats=mats)


def evaluate(kappa: np.ndarray, theta: np.ndarray, sizes: tuple[int, ...] = LAYER_SIZES) -> np.ndarray:
    """Phi(kappa, theta) only (paper 004 eq. 2 with the tanh output of §6)."""
    return forward(kappa, theta, sizes).output


def jacobian(fwd: Forward, sizes: tuple[int, ...] = LAYER_SIZES) -> np.ndarray:
    """grad_theta Phi at the weights of the forward pass `fwd`, (L_{k+1}, p): paper 004 eq. 3
    times diag(1 - Phi^2) for the tanh output.

    Block j is (prod_{l=k}^{j+1} V_{l+1}^T dphi_l/dvarphi_{l-1}) (I_{L_{j+1}} kron varrho_j),
    built backwards from the output layer.
    """
    mats = fwd.mats
    k = len(mats) - 1
    n_out = sizes[-1]
    back = np.diag(1.0 - fwd.output**2)  # d Phi / d varphi_k
    out = np.empty((n_out, n_params(sizes)))
    end = out.shape[1]
    for j in range(k, -1, -1):
        a = fwd.inputs[j]  # varrho_j^T, length L_j^a
        width = back.shape[1] * a.size
        # (back @ (I kron a^T))[:, m * L^a + l] = back[:, m] * a[l]
        out[:, end - width:end] = (back[:, :, None] * a[None, None, :]).reshape(n_out, width)
        end -= width
        if j > 0:
            # d varphi_j / d varphi_{j-1} = V_{j+1}^T dphi_j/dvarphi_{j-1} (bias row drops out)
            back = (back @ mats[j][:-1, :].T) * swish_prime(fwd.pre[j - 1])[None, :]
    return out


def kaiming_init(rng: np.random.Generator, sizes: tuple[int, ...] = LAYER_SIZES) -> np.ndarray:
    """He-normal weights, std sqrt(2 / fan_in), zero biases (paper 004 §6, ref. [39]).

    The paper does not say how the bias rows are initialised; zeros is the usual He convention.
    """
    mats = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        v = np.zeros((a + 1, b))
        v[:a, :] = rng.normal(0.0, np.sqrt(2.0 / a), size=(a, b))
        mats.append(v)
    return pack(mats)
