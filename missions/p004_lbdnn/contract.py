"""Paper 004's contract: what the plant's sensing kind and the servicers' flight software share.

Imports nothing of the project but `bus` (here: nothing at all); numpy only. Read by
missions/p004_lbdnn/sense.py (the sensor `p004-partial`), missions/p004_lbdnn/fsw/ (the flight
software) and the paper's report (missions/p004_lbdnn/report/). docs/architecture.md "Mission rooms
(issue 25)".

**Names.** `CONTROLLER` is the name the flight software registers and the sensing kind looks for
(the servicers it measures for). The measurements arrive in `Observation.extra` as named arrays
(bus/codec.py add_measurement, "<name>/<subject>"), in inertial axes (ECI), metres:

    "p004.d_m/<j>"       d_ij = q_j - q_i + noise, (3,), one per graph neighbour j (eq. 9)
    "p004.y_m/<defunct>" y_i = C_i (q0 - q_i) + noise, (m_i,), when b_i = 1 (eq. 10)

**Parameter model** of the `[controller.params]` of p004-lbdnn: gains, output matrices C_i, b_i and
the graph (`mission_from_params`). The plant reads the graph, C_i and b_i from the same parameters
the flight software flies with, so there is one source of truth for them.

The paper's values (§6): k1..k5 = 0.65, k6 = 1e-4, Gamma_i = 0.01 I_103, the six C_i printed
in §6. Not given, chosen here (docs/paper004.md): the graph (Fig. 1 is missing: a ring
s1-s2-...-s6-s1), b_i = 1 for every servicer (§6: "each servicer spacecraft employs an output
matrix C_i"), the projection bound theta_bar and its boundary layer, the seed of the initial weights.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

CONTROLLER = "p004-lbdnn"
"""The servicers' controller name (registered by missions/p004_lbdnn/fsw/controller.py)."""
KEY_D = "p004.d_m"
"""d_ij = q_j - q_i + noise, (3,) metres, inertial axes: obs.extra[f"{KEY_D}/{j}"] per neighbour j (eq. 9)."""
KEY_Y = "p004.y_m"
"""y_i = C_i (q0 - q_i) + noise, (m_i,) metres, inertial axes; subject: the defunct craft's id (eq. 10)."""

PAPER_C: dict[str, tuple[tuple[float, ...], ...]] = {
    "s1": ((1.5124, -1.8904, 0.6818),),
    "s2": ((-0.2772, 1.7565, 1.1135), (0.8638, 1.2110, -1.6287)),
    "s3": ((1.5055, 1.5784, -1.6598), (-1.8437, -1.3206, 1.5125)),
    "s4": ((0.3722, 0.6866, -0.3528), (-1.2097, -0.8414, -1.4315), (1.1332, -0.3498, -1.8633)),
    "s5": ((1.9554, 0.9926, -0.8782), (1.1571, -1.5870, -0.2084), (1.6343, -0.8255, -0.8488)),
    "s6": ((0.0991, -1.6655, 1.6674),),
}
"""Output matrices C_1..C_6 of paper 004 §6 (rows act on q0 - q_i, inertial axes here)."""

SERVICERS: tuple[str, ...] = ("s1", "s2", "s3", "s4", "s5", "s6")
RING_EDGES: tuple[tuple[str, str], ...] = tuple(
    (SERVICERS[i], SERVICERS[(i + 1) % 6]) for i in range(6))
PATH_EDGES: tuple[tuple[str, str], ...] = tuple(
    (SERVICERS[i], SERVICERS[i + 1]) for i in range(5))


@dataclass(frozen=True)
class Gains:
    """k1..k6 and Gamma of paper 004 eqs. 14, 24-28 (values of §6)."""

    k1: float = 0.65
    k2: float = 0.65
    k3: float = 0.65
    k4: float = 0.65
    k5: float = 0.65
    k6: float = 1e-4
    gamma: float = 0.01  # Gamma_i = gamma * I_p

    def __post_init__(self) -> None:
        for name in ("k1", "k2", "k3", "k4", "k5", "k6", "gamma"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"gain {name} must be > 0, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class ServicerConfig:
    """Everything servicer i's flight software knows of itself and its graph (paper 004 §3.3)."""

    sc_id: str
    neighbours: tuple[str, ...]
    c_matrix: np.ndarray  # C_i, (m_i, 3)
    b: int  # b_i in {0, 1}: does i measure y_i = C_i (q0 - q_i)
    gains: Gains = field(default_factory=Gains)
    theta_bar: float = 30.0  # projection bound on ||theta_hat_i|| (Assumption 3), chosen
    proj_epsilon: float = 1.0  # boundary layer of the smooth projection (Krstic App. E), chosen
    use_network: bool = True  # False: Phi == 0 and no adaptation (the ablation of NOTES-004)
    weight_seed: int = 0  # seed of the Kaiming initial weights
    rk4_substeps: int = 1  # internal integration steps per control step
    max_accel_mps2: float | None = None  # per-axis thrust limit (None: the paper's case, none)

    def __post_init__(self) -> None:
        c = np.atleast_2d(np.asarray(self.c_matrix, dtype=float))
        if c.ndim != 2 or c.shape[1] != 3:
            raise ValueError(f"{self.sc_id}: C_i must be (m_i, 3), got shape {c.shape}")
        object.__setattr__(self, "c_matrix", c)
        if self.b not in (0, 1):
            raise ValueError(f"{self.sc_id}: b_i must be 0 or 1, got {self.b!r}")
        if self.sc_id in self.neighbours:
            raise ValueError(f"{self.sc_id}: a servicer is not its own neighbour (no self-loops)")
        if not self.theta_bar > 0.0 or not self.proj_epsilon > 0.0:
            raise ValueError(f"{self.sc_id}: theta_bar and proj_epsilon must be > 0")
        if self.rk4_substeps < 1:
            raise ValueError(f"{self.sc_id}: rk4_substeps must be >= 1, got {self.rk4_substeps}")
        if self.max_accel_mps2 is not None and not self.max_accel_mps2 > 0.0:
            raise ValueError(f"{self.sc_id}: max_accel_mps2 must be > 0 or None, got {self.max_accel_mps2}")

    @property
    def ctc(self) -> np.ndarray:
        """b_i C_i^T C_i, the servicer's own block of C in eq. 29."""
        return self.b * self.c_matrix.T @ self.c_matrix


@dataclass(frozen=True)
class MissionConfig:
    """The whole network: servicer ids, undirected edges, C_i and b_i, shared gains."""

    servicers: tuple[str, ...] = SERVICERS
    edges: tuple[tuple[str, str], ...] = RING_EDGES
    c_matrices: dict[str, np.ndarray] = field(
        default_factory=lambda: {k: np.array(v) for k, v in PAPER_C.items()})
    b: dict[str, int] = field(default_factory=lambda: {k: 1 for k in SERVICERS})
    gains: Gains = field(default_factory=Gains)
    theta_bar: float = 30.0
    proj_epsilon: float = 1.0
    use_network: bool = True
    seed: int = 0
    rk4_substeps: int = 1
    max_accel_mps2: float | None = None

    def __post_init__(self) -> None:
        ids = set(self.servicers)
        for a, c in self.edges:
            if a not in ids or c not in ids or a == c:
                raise ValueError(f"edge ({a!r}, {c!r}) is not between two distinct servicers")
        missing = ids - set(self.c_matrices) | ids - set(self.b)
        if missing:
            raise ValueError(f"no C_i / b_i for {sorted(missing)}")

    def neighbours(self, sc_id: str) -> tuple[str, ...]:
        """N_i of the undirected graph, in the order of `servicers`."""
        nb = {c for a, c in self.edges if a == sc_id} | {a for a, c in self.edges if c == sc_id}
        return tuple(s for s in self.servicers if s in nb)

    def servicer(self, sc_id: str) -> ServicerConfig:
        if sc_id not in self.servicers:
            raise ValueError(f"unknown servicer {sc_id!r}; known: {list(self.servicers)}")
        return ServicerConfig(
            sc_id=sc_id, neighbours=self.neighbours(sc_id), c_matrix=self.c_matrices[sc_id],
            b=int(self.b[sc_id]), gains=self.gains, theta_bar=self.theta_bar,
            proj_epsilon=self.proj_epsilon, use_network=self.use_network,
            weight_seed=self.seed * 1000 + self.servicers.index(sc_id),
            rk4_substeps=self.rk4_substeps, max_accel_mps2=self.max_accel_mps2)

    def laplacian(self) -> np.ndarray:
        """L = D - A of the undirected graph (paper 004 §2.1)."""
        n = len(self.servicers)
        idx = {s: i for i, s in enumerate(self.servicers)}
        a = np.zeros((n, n))
        for s, c in self.edges:
            a[idx[s], idx[c]] = a[idx[c], idx[s]] = 1.0
        return np.diag(a.sum(axis=1)) - a

    def interaction_matrix(self) -> np.ndarray:
        """H = L kron I_3 + blkdiag(b_i C_i^T C_i) (paper 004 eq. 29)."""
        h = np.kron(self.laplacian(), np.eye(3))
        for i, s in enumerate(self.servicers):
            c = np.atleast_2d(self.c_matrices[s])
            h[3 * i:3 * i + 3, 3 * i:3 * i + 3] += self.b[s] * c.T @ c
        return h

    def lambda_min_h(self) -> float:
        """lambda_min(H): positive iff trackable on a connected graph (Lemma 1)."""
        return float(np.linalg.eigvalsh(self.interaction_matrix())[0])

    def trackable(self) -> bool:
        """Definition 1: rank(sum_i b_i C_i^T C_i) = 3."""
        s = sum(self.b[k] * np.atleast_2d(self.c_matrices[k]).T @ np.atleast_2d(self.c_matrices[k])
                for k in self.servicers)
        return int(np.linalg.matrix_rank(s)) == 3


def mission_from_params(params: dict[str, Any]) -> MissionConfig:
    """A MissionConfig from a scenario's `[controller]` table; absent keys keep the defaults.

    Keys: servicers (list), edges (list of [a, b]), graph ("ring" | "path", instead of edges),
    b ({id: 0/1}), C ({id: rows}), gains ({k1..k6, gamma}), theta_bar, proj_epsilon,
    use_network, seed, rk4_substeps, max_accel_mps2 (a stated variant: the paper has no limit).
    """
    known = {"servicers", "edges", "graph", "b", "C", "gains", "theta_bar", "proj_epsilon",
             "use_network", "seed", "rk4_substeps", "max_accel_mps2"}
    unknown = set(params) - known
    if unknown:
        raise ValueError(f"unknown p004-lbdnn parameters {sorted(unknown)}; known: {sorted(known)}")
    cfg = MissionConfig()
    kw: dict[str, Any] = {}
    if "servicers" in params:
        kw["servicers"] = tuple(params["servicers"])
    if "graph" in params:
        graphs = {"ring": RING_EDGES, "path": PATH_EDGES}
        if params["graph"] not in graphs:
            raise ValueError(f"graph {params['graph']!r}: expected one of {sorted(graphs)}")
        kw["edges"] = graphs[params["graph"]]
    if "edges" in params:
        kw["edges"] = tuple((str(a), str(c)) for a, c in params["edges"])
    if "C" in params:
        kw["c_matrices"] = {k: np.atleast_2d(np.asarray(v, dtype=float)) for k, v in params["C"].items()}
    if "b" in params:
        kw["b"] = {**cfg.b, **{k: int(v) for k, v in params["b"].items()}}
    if "gains" in params:
        kw["gains"] = replace(cfg.gains, **{k: float(v) for k, v in params["gains"].items()})
    for key, cast in (("theta_bar", float), ("proj_epsilon", float), ("use_network", bool),
                      ("seed", int), ("rk4_substeps", int), ("max_accel_mps2", float)):
        if key in params:
            kw[key] = cast(params[key])
    return replace(cfg, **kw)
