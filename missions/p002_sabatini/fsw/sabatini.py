"""Behavioural swarm keeping of paper 002 (sections 3.3-3.8) as flight software.

Every decision step, for each visible neighbour k, spacecraft j:

1. turns the measured LVLH state of k relative to j (r_k - r_j) into the ROE of j relative to k,
   dalpha_jk = M(u) (r_j - r_k) (NOTES-002: the observer relative to the neighbour, so j's own
   thrust enters through +B(u) and the CA offset da = +100 m makes j drift back, away from k);
2. computes the decision distance d_min_jk = |a dl| - 2 |a de| (section 3.3) and picks
   collision avoidance (d_min_jk < d_min), attraction (d_min_jk > 0.6 d_max) or alignment;
3. builds the behaviour's reference state (sections 3.5-3.7, Algorithm 1):
   - CA: de_ref = k_ecc d_min_trans de/|de|, di_ref = de_ref, da_ref = +100 m, weight 1;
   - alignment: if TooSmall, TooLarge (d_max_trans = 0.9 d_jk tan theta_fov) or NotParallel,
     de_ref, di_ref as CA; otherwise de, di are left as they are; da_ref = 0; the weight falls
     linearly from 1 at d_min_jk = d_min to 0 at d_min_jk = 0.6 d_max;
   - attraction: da_ref = 0 (only da is weighted), weight 1;
4. sums u_c = -sum_k w_jk K_b(u) (dalpha_jk - dalpha_ref_jk) with the periodic DRE gains of each
   behaviour (missions/p002_sabatini/fsw/dre.py) and clips each axis to the actuator limit.

Choices where the paper is silent (documented, not tuned): d_jk in d_max_trans is the measured
range |r_k - r_j|; when |de| = 0 the reference direction is that of di, or radial (1, 0) if both
vanish; the parallelism of a pair with |de| or |di| = 0 is 0 (NotParallel). dl of the reference is
the measured one: dl is not weighted in any Q, so the DRE gives it no gain.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from swarmhil.agent.controller import Command, CommandBatch, Decision, DecisionRows, Observation, ObservationBatch, OrbitInfo, register
from swarmhil.agent.roe import lvlh_to_roe, observer_roe_rows
from swarmhil.missions.p002_sabatini.contract import CONTROLLER, D_MIN_M, D_MIN_TRANS_M, PARALLEL_MIN
from swarmhil.missions.p002_sabatini.fsw.dre import GainTable, gain_table, interpolate_periodic, stacked_gains

CA, ALIGN, ALIGN_DRIFT, ATTRACT = "collision_avoidance", "alignment", "alignment_drift", "attraction"
_TINY_M = 1e-9


@dataclass(frozen=True)
class SabatiniParams:
    """Parameters of the behavioural law; defaults are the paper's (section 3, NOTES-002)."""

    d_min_m: float = D_MIN_M  # along-track minimum distance (section 3.2)
    d_min_trans_m: float = D_MIN_TRANS_M  # radial / cross-track minimum distance
    d_max_m: float = 500.0  # detection range
    attraction_fraction: float = 0.6  # attraction when d_min_jk > 0.6 d_max (section 3.3)
    k_ecc: float = 1.1
    ca_da_offset_m: float = 100.0  # a * da_ref of collision avoidance (section 3.5)
    parallel_min: float = PARALLEL_MIN  # NotParallel when |de.di|/(|de||di|) < 0.8 (Algorithm 1)
    fov_margin: float = 0.9  # d_max_trans = 0.9 d_jk tan(theta_fov)
    fov_half_angle_deg: float = float(np.degrees(np.arctan(0.54)))  # 1080 px, f = 1000 px: 28.37 deg
    q_ca: tuple[float, ...] = (0.01, 0.0, 1.0, 1.0, 1.0, 1.0)
    q_al: tuple[float, ...] = (1.0, 0.0, 1.0, 1.0, 1.0, 1.0)
    q_att: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    r_ca_si: float = 1e-2  # paper 1e4 I3 in (km/s^2)^-2
    r_al_si: float = 1.0  # paper 1e6
    r_att_si: float = 1e-1  # paper 1e5
    # per-axis actuator clip; the paper (section 4.2, Fig. 19) only says "milli-newton-level
    # thrusters" for ~10 kg spacecraft (~1e-4 m/s^2); the two-satellite cases peak at 4.5e-5 m/s^2
    max_accel_mps2: float = 1e-3
    enable_collision_avoidance: bool = True
    enable_alignment: bool = True
    enable_attraction: bool = True
    dre_table_size: int = 720  # gain table nodes per orbit (0.5 deg; a 10 s step is 0.63 deg)

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> "SabatiniParams":
        known = {f.name: f for f in fields(cls)}
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise ValueError(f"unknown sabatini controller params {unknown}; known: {sorted(known)}")
        kw: dict[str, Any] = {}
        for key, value in params.items():
            default = known[key].default
            if isinstance(default, tuple):
                kw[key] = tuple(float(x) for x in value)
                if len(kw[key]) != 6:
                    raise ValueError(f"{key} must have 6 entries, got {value!r}")
            elif isinstance(default, bool):
                kw[key] = bool(value)
            elif isinstance(default, int):
                kw[key] = int(value)
            else:
                kw[key] = float(value)
        return cls(**kw)


def relative_roe_observer(rel_position_m: np.ndarray, rel_velocity_mps: np.ndarray, u_rad: float,
                          n_radps: float) -> np.ndarray:
    """dalpha_jk in metres: ROE of the observer j relative to neighbour k from the measured r_k - r_j."""
    return lvlh_to_roe(-np.asarray(rel_position_m, float), -np.asarray(rel_velocity_mps, float), u_rad, n_radps)


def decision_distance_m(roe_jk_m: np.ndarray) -> np.ndarray:
    """d_min_jk = a(|dl| - 2|de|), the minimum along-track distance over an orbit (section 3.3)."""
    return np.abs(roe_jk_m[..., 1]) - 2.0 * np.hypot(roe_jk_m[..., 2], roe_jk_m[..., 3])


def parallelism(roe_jk_m: np.ndarray, de_m: np.ndarray | None = None, di_m: np.ndarray | None = None) -> np.ndarray:
    """|de . di| / (|de| |di|), 0 when either vector vanishes (Algorithm 1, step 3); |de|, |di|
    (np.hypot of the components) are computed unless given."""
    r = roe_jk_m
    de_m = np.hypot(r[..., 2], r[..., 3]) if de_m is None else de_m
    di_m = np.hypot(r[..., 4], r[..., 5]) if di_m is None else di_m
    den = de_m * di_m
    prod = r[..., 2:4] * r[..., 4:6]  # dex dix, dey diy
    dot = np.abs(prod[..., 0] + prod[..., 1])
    ok = den > _TINY_M**2
    return np.where(ok, dot / np.where(ok, den, 1.0), 0.0)


def safe_direction(roe_jk_m: np.ndarray, de_m: np.ndarray | None = None, di_m: np.ndarray | None = None) -> np.ndarray:
    """(N,2) unit vector along de (fallback di, then (1, 0)) for the de/di reference of sections 3.5-3.6;
    |de|, |di| (N,) computed unless given."""
    de, di = roe_jk_m[:, 2:4], roe_jk_m[:, 4:6]
    nde = np.hypot(de[:, :1], de[:, 1:]) if de_m is None else de_m[:, None]
    ndi = np.hypot(di[:, :1], di[:, 1:]) if di_m is None else di_m[:, None]
    ok = ndi > _TINY_M
    out = np.where(ok, di / np.where(ok, ndi, 1.0), _RADIAL)
    ok = nde > _TINY_M
    return np.where(ok, de / np.where(ok, nde, 1.0), out)


_RADIAL = np.array([[1.0, 0.0]])  # safe_direction's last fallback, (1, 0)


class SabatiniController:
    """Behavioural controller (collision avoidance / alignment / attraction) of paper 002."""

    name = "sabatini"

    def __init__(self, sc_id: str, orbit: OrbitInfo, params: SabatiniParams) -> None:
        self.sc_id = sc_id
        self.a_m = float(orbit.semi_major_axis_m)
        self.n_radps = float(orbit.mean_motion_radps)
        self.p = params
        self.tan_fov = float(np.tan(np.radians(params.fov_half_angle_deg)))
        self.gains: dict[str, GainTable] = {
            CA: gain_table(self.a_m, self.n_radps, params.q_ca, params.r_ca_si, params.dre_table_size),
            ALIGN: gain_table(self.a_m, self.n_radps, params.q_al, params.r_al_si, params.dre_table_size),
            ATTRACT: gain_table(self.a_m, self.n_radps, params.q_att, params.r_att_si, params.dre_table_size),
        }
        self._enabled = {CA: params.enable_collision_avoidance, ALIGN: params.enable_alignment,
                         ATTRACT: params.enable_attraction}
        self._enabled_codes = np.array([self._enabled[b] for b in (CA, ALIGN, ATTRACT)])
        # each decision's label by 2 (behaviour code) + (corrected): DecisionRows.labels
        self._decision_labels = tuple(_label(b, ok, self._enabled) for b in BEHAVIOURS for ok in (False, True))
        self._gain_stack = stacked_gains(tuple(self.gains[b] for b in (CA, ALIGN, ATTRACT)))
        self._d_att_m = params.attraction_fraction * params.d_max_m
        self._span_m = params.attraction_fraction * params.d_max_m - params.d_min_m

    def classify(self, d_min_jk_m: np.ndarray) -> np.ndarray:
        """Behaviour of each pair from its decision distance (section 3.3)."""
        return np.array(self._labels(np.asarray(d_min_jk_m, float).tolist()), dtype=object)

    def _labels(self, d_min_jk_m: list[float]) -> list[str]:
        # the same comparisons as np.where(d < d_min, CA, np.where(d > 0.6 d_max, ATTRACT, ALIGN)),
        # on Python floats (a NaN is ALIGN in both)
        d_min, d_att = self.p.d_min_m, self._d_att_m
        return [CA if d < d_min else (ATTRACT if d > d_att else ALIGN) for d in d_min_jk_m]

    def references(self, roe_jk_m: np.ndarray, range_m: np.ndarray, behaviour: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(reference ROE (N,6), weight (N,), alignment-correcting flag (N,)) per pair (sections 3.5-3.7)."""
        return self._references(roe_jk_m, range_m, behaviour == CA, behaviour == ALIGN, behaviour == ATTRACT,
                                decision_distance_m(roe_jk_m))

    def _references(self, roe_jk_m: np.ndarray, range_m: np.ndarray, is_ca: np.ndarray, is_al: np.ndarray,
                    is_att: np.ndarray, d_min_jk_m: np.ndarray, de_m: np.ndarray | None = None,
                    di_m: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p = self.p
        ref = roe_jk_m.copy()
        de_m = np.hypot(roe_jk_m[:, 2], roe_jk_m[:, 3]) if de_m is None else de_m
        di_m = np.hypot(roe_jk_m[:, 4], roe_jk_m[:, 5]) if di_m is None else di_m
        d_max_trans_m = p.fov_margin * range_m * self.tan_fov
        # (di > d or de > d) is fmax(di, de) > d, and (di < d or de < d) is fmin(di, de) < d: fmax and
        # fmin give the other operand when one is NaN (a NaN compares False), NaN when both are
        too_large = np.fmax(di_m, de_m) > d_max_trans_m
        too_small = np.fmin(di_m, de_m) < p.d_min_trans_m
        not_parallel = parallelism(roe_jk_m, de_m, di_m) < p.parallel_min
        correct = is_ca | (is_al & (too_large | too_small | not_parallel))
        if correct.any():  # the safe direction only where it is used (elementwise: the same values)
            safe = p.k_ecc * p.d_min_trans_m * safe_direction(roe_jk_m[correct], de_m[correct], di_m[correct])
            ref[correct, 2:4] = safe
            ref[correct, 4:6] = safe
        ref[:, 0] = np.where(is_ca, p.ca_da_offset_m, 0.0)
        ref[is_att, 2:6] = 0.0  # unweighted in Q_att; the reference of section 3.7 is zero
        w_al = ((self._d_att_m - d_min_jk_m) / self._span_m).clip(0.0, 1.0)  # ndarray.clip: np.clip without its wrapper
        weight = np.where(is_al, w_al, 1.0)
        return ref, weight, correct

    def step(self, obs: Observation) -> Command:
        """This spacecraft's command: the law of `step_batch` on a batch of one (one implementation,
        so an agent process and a batch run give the same command, bit for bit)."""
        n = len(obs.neighbour_ids)
        batch = ObservationBatch(step=obs.step, t_s=obs.t_s, u_rad=obs.u_rad, observers=[self.sc_id],
                                 offsets=np.array([0, n], dtype=np.int64), neighbour_ids=list(obs.neighbour_ids),
                                 rel_position_m=np.asarray(obs.rel_position_m, float).reshape(n, 3),
                                 rel_velocity_mps=np.asarray(obs.rel_velocity_mps, float).reshape(n, 3))
        return self._step_pairs(batch).command(0)

    @classmethod
    def step_batch(cls, controllers: "list[SabatiniController]", batch: ObservationBatch) -> CommandBatch:
        """The commands of many spacecraft at once (issue 16): every visible pair of the batch in
        one pass of numpy. Each pair's arithmetic is elementwise (or a per-pair matrix-vector
        product, the same BLAS call as `g @ err`), and each spacecraft's sum over its neighbours is
        sequential in neighbour order from +0.0, so a spacecraft's command does not depend on the
        batch it is in (tests/test_behaviour_batch.py); the truth checksums (tests/test_truth_checksums.py)
        are those of the per-spacecraft code this replaced. Controllers with different parameters or
        orbits are stepped one by one."""
        if not controllers:
            return CommandBatch(np.zeros((0, 3)), [])
        if not _alike(controllers):
            return CommandBatch.of([c.step(batch.observation(i)) for i, c in enumerate(controllers)])
        return controllers[0]._step_pairs(batch)

    def _step_pairs(self, batch: ObservationBatch) -> CommandBatch:
        """Sections 3.3-3.8 for every pair (j observer, k neighbour) of the batch."""
        n_obs = len(batch)
        off = np.asarray(batch.offsets, dtype=np.int64)
        counts = off[1:] - off[:-1]
        n_pairs = int(off[-1]) if n_obs else 0
        if n_pairs == 0:
            return CommandBatch(np.zeros((n_obs, 3)), ["search"] * n_obs, build=_searching,
                                decision_rows=DecisionRows(off, [], (), np.zeros(0, dtype=np.int64), np.zeros(0),
                                                           np.zeros((0, 6)), np.zeros((0, 3))))
        owner = batch.owners()  # the observer of each pair
        rel_pos = np.asarray(batch.rel_position_m, float).reshape(n_pairs, 3)
        rel_vel = np.asarray(batch.rel_velocity_mps, float).reshape(n_pairs, 3)
        u = batch.u_rad
        roe_jk_m = observer_roe_rows(rel_pos, rel_vel, u, self.n_radps)  # relative_roe_observer, bit for bit
        de_di = np.hypot(roe_jk_m[:, 2::2], roe_jk_m[:, 3::2])  # |de|, |di| of each pair in one call
        de_m, di_m = de_di[:, 0], de_di[:, 1]
        d_min_jk_m = np.abs(roe_jk_m[:, 1]) - 2.0 * de_m  # decision_distance_m
        # behaviour of each pair (section 3.3): CA below d_min, attraction above 0.6 d_max, else
        # alignment (a NaN distance is alignment)
        is_ca = d_min_jk_m < self.p.d_min_m
        is_att = ~is_ca & (d_min_jk_m > self._d_att_m)
        is_al = ~(is_ca | is_att)
        code = np.where(is_ca, 0, np.where(is_att, 2, 1))  # index into BEHAVIOURS
        range_m = np.sqrt(np.einsum("ij,ij->i", rel_pos, rel_pos))
        ref, weight, correct = self._references(roe_jk_m, range_m, is_ca, is_al, is_att, d_min_jk_m, de_m, di_m)
        err = roe_jk_m - ref
        # u_c = -sum_k w_jk K_b(u) (dalpha_jk - dalpha_ref_jk), the gains of the enabled behaviours
        on_b = self._enabled_codes
        gains = interpolate_periodic(self._gain_stack, u, axis=1)  # (3 behaviours, 3, 6): GainTable.gain of each
        if on_b.all():
            contrib = -weight[:, None] * np.matmul(gains[code], err[:, :, None])[:, :, 0]
            prio = code
        else:
            contrib = np.zeros((n_pairs, 3))
            on = on_b[code]
            if on.any():
                contrib[on] = -weight[on][:, None] * np.matmul(gains[code[on]], err[on][:, :, None])[:, :, 0]
            prio = np.where(on, code, len(BEHAVIOURS))
        # each observer's sum over its neighbours, in order, from +0.0 (unbuffered, sequential)
        total = np.zeros((n_obs, 3))
        np.add.at(total, owner, contrib)
        accel = total.clip(-self.p.max_accel_mps2, self.p.max_accel_mps2)  # (ndarray.clip: the same ufunc)
        # mode: the first enabled behaviour present (CA, alignment, attraction), else coast; search
        # without neighbours
        first = np.full(n_obs, len(BEHAVIOURS))
        np.minimum.at(first, owner, prio)
        modes = [_MODES[f] if c else "search" for f, c in zip(first.tolist(), counts.tolist())]
        enabled = self._enabled

        def build(i: int) -> Command:
            """Observer i's full Command with its decisions (telemetry)."""
            a, b_ = int(off[i]), int(off[i + 1])
            if a == b_:
                return _searching(i)
            decisions = []
            for r, c, ok in zip(range(a, b_), code[a:b_].tolist(), correct[a:b_].tolist()):
                decisions.append(Decision(neighbour=batch.neighbour_ids[r], behaviour=_label(BEHAVIOURS[c], ok, enabled),
                                          d_min_m=float(d_min_jk_m[r]), roe_rel_m=roe_jk_m[r].copy(),
                                          accel_mps2=contrib[r].copy()))
            return Command(accel_mps2=accel[i].copy(), mode=modes[i], decisions=decisions)

        # the labels of `build` as arrays: label 2 code + corrected
        rows = DecisionRows(off, batch.neighbour_ids, self._decision_labels, 2 * code + correct, d_min_jk_m, roe_jk_m, contrib)
        return CommandBatch(accel_mps2=accel, modes=modes, build=build, decision_rows=rows)


def _label(b: str, corrected: bool, enabled: dict[str, bool]) -> str:
    """A decision's behaviour label: the behaviour, `_disabled` when it is off, alignment without
    correction `alignment_drift`."""
    if not enabled[b]:
        return f"{b}_disabled"
    return ALIGN_DRIFT if b == ALIGN and not corrected else b


BEHAVIOURS = (CA, ALIGN, ATTRACT)
_MODES = (*BEHAVIOURS, "coast")


def _searching(_i: int) -> Command:
    return Command(accel_mps2=np.zeros(3), mode="search", decisions=[])


_ALIKE: list = [([], False)]  # the last controllers checked (kept alive: identity means the same objects)


def _alike(controllers: "list[SabatiniController]") -> bool:
    """Same parameters and orbit for all (one vectorised law); the verdict of the last list is kept,
    since a batch run asks about the same controllers every step."""
    last, verdict = _ALIKE[0]
    if last == controllers:  # element by element, by identity (the controllers define no __eq__)
        return verdict
    c0 = controllers[0]
    verdict = all(c.p == c0.p and c.a_m == c0.a_m and c.n_radps == c0.n_radps for c in controllers[1:])
    _ALIKE[0] = (list(controllers), verdict)
    return verdict


def _check_sabatini(params: dict[str, Any]) -> None:
    SabatiniParams.from_dict(dict(params))


@register(CONTROLLER, validate=_check_sabatini)
def make_sabatini(sc_id: str, orbit: OrbitInfo, params: dict[str, Any]) -> SabatiniController:
    """Factory for the controller registry: (sc_id, orbit, [controller.params]) -> controller
    (scipy is imported on use, by the DRE solve of a table not on disk)."""
    return SabatiniController(sc_id, orbit, SabatiniParams.from_dict(dict(params)))
