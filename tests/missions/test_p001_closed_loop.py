"""Paper 001 closed loop in one process: six spacecraft from a 1000 m sphere to a hexagon of side 10 m.

The plant here is independent of the room: the exact CW state-transition matrix with the command
held over each step (zero-order hold, from the matrix exponential of the CW system), sensing
synthesised from truth (neighbours within the 21 m ball, own state in Observation.extra).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
from scipy.linalg import expm

from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.missions.p001_lattice.contract import check_hexagon, hexagon_vertices, structure_name
from swarmhil.missions.p001_lattice.fsw.sensing import OwnState
from swarmhil.claims.check import claim_failures
from swarmhil.claims.registry import registry

N_GEO = 7.2921e-5
R_SENSE_M = 21.0
SIDE_M = 10.0


def cw_zoh(n: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discrete CW: X+ = Phi X + Gamma u (u held over dt), from expm of the augmented system."""
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0], a[3, 4] = 3 * n * n, 2 * n
    a[4, 3] = -2 * n
    a[5, 2] = -n * n
    m = np.zeros((9, 9))
    m[:6, :6] = a
    m[3:6, 6:9] = np.eye(3)
    e = expm(m * dt)
    return e[:6, :6], e[:6, 6:9]


def sphere_directions(seed: int | None, count: int = 6) -> np.ndarray:
    """Release directions: seed None = the octahedron (+-x, +-y, +-z); else uniform on the sphere."""
    if seed is None:
        return np.vstack([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5]]
    v = np.random.default_rng(seed).normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@dataclass
class Run:
    t_s: np.ndarray
    pos_m: np.ndarray  # (steps+1, N, 3)
    vel_mps: np.ndarray
    acc_mps2: np.ndarray  # (steps, N, 3)
    modes: list[list[str]]
    dt_s: float
    layer_times_s: dict[str, list[float]] = field(default_factory=dict)

    @property
    def delta_v_mps(self) -> np.ndarray:
        return np.sum(np.linalg.norm(self.acc_mps2, axis=2), axis=0) * self.dt_s


def simulate(directions: np.ndarray, duration_s: float, dt_s: float = 1.0, params: dict | None = None,
             radius_m: float = 1000.0, record_every: int = 1) -> Run:
    n_sc = directions.shape[0]
    ids = [f"sc{i}" for i in range(n_sc)]
    orbit = OrbitInfo(semi_major_axis_m=42164e3, mean_motion_radps=N_GEO)
    ctrls = [make_controller("p001-lattice", i, orbit, dict(params or {})) for i in ids]
    phi, gam = cw_zoh(N_GEO, dt_s)
    x = np.zeros((n_sc, 6))
    x[:, :3] = radius_m * directions
    steps = int(round(duration_s / dt_s))
    ts, ps, vs, accs, modes = [0.0], [x[:, :3].copy()], [x[:, 3:].copy()], [], []
    first = {"near": [np.nan] * n_sc, "shaping": [np.nan] * n_sc}
    for k in range(steps):
        t = k * dt_s
        u = np.zeros((n_sc, 3))
        mk = []
        dist = np.linalg.norm(x[None, :, :3] - x[:, None, :3], axis=2)
        for i, c in enumerate(ctrls):
            rel = x[:, :3] - x[i, :3]
            seen = [j for j in range(n_sc) if j != i and dist[i, j] <= R_SENSE_M]
            obs = Observation(step=k, t_s=t, u_rad=N_GEO * t, neighbour_ids=[ids[j] for j in seen],
                              rel_position_m=rel[seen].reshape(-1, 3),
                              rel_velocity_mps=(x[seen, 3:] - x[i, 3:]).reshape(-1, 3),
                              extra=OwnState(x[i, :3].copy(), x[i, 3:].copy()).to_extra())
            cmd = c.step(obs)
            u[i] = cmd.accel_mps2
            mk.append(cmd.mode)
            if cmd.mode in first and np.isnan(first[cmd.mode][i]):
                first[cmd.mode][i] = t
        x = x @ phi.T + u @ gam.T
        accs.append(u)
        if (k + 1) % record_every == 0:
            ts.append((k + 1) * dt_s)
            ps.append(x[:, :3].copy())
            vs.append(x[:, 3:].copy())
            modes.append(mk)
    return Run(np.array(ts), np.array(ps), np.array(vs), np.array(accs), modes, dt_s, first)


def time_to_form(run: Run, hold_s: float = 1000.0) -> float:
    """First time after which the geometric hexagon test holds for hold_s and to the end (nan if never)."""
    ok = np.array([check_hexagon(p, SIDE_M).is_hexagon for p in run.pos_m])
    if not ok[-1]:
        return float("nan")
    bad = np.flatnonzero(~ok)
    start = 0 if bad.size == 0 else bad[-1] + 1
    t0 = float(run.t_s[start])
    return t0 if run.t_s[-1] - t0 >= hold_s else float("nan")


def summary(run: Run) -> dict:
    hx = check_hexagon(run.pos_m[-1], SIDE_M)
    d = np.linalg.norm(run.pos_m[:, :, None, :] - run.pos_m[:, None, :, :], axis=3)
    iu = np.triu_indices(run.pos_m.shape[1], 1)
    return {
        "structure": structure_name(run.pos_m[-1], SIDE_M), "hexagon": hx.is_hexagon, "ring": hx.ring, "sides_m": (round(hx.side_min_m, 3), round(hx.side_max_m, 3)),
        "angles_deg": (round(hx.angle_min_deg, 1), round(hx.angle_max_deg, 1)),
        "thickness_m": round(hx.thickness_m, 3), "normal_x": round(hx.normal_x, 4),
        "centre_m": np.round(hx.centre_m, 2).tolist(), "phase_deg": round(hx.phase_deg, 1),
        "eq16": round(hx.eq16, 4), "t_form_s": time_to_form(run),
        "t_middle_s": run.layer_times_s["near"], "t_inner_s": run.layer_times_s["shaping"],
        "v_max_mps": round(float(np.max(np.linalg.norm(run.vel_mps, axis=2))), 4),
        "u_max_mps2": float(np.max(np.linalg.norm(run.acc_mps2, axis=2))),
        "d_min_m": round(float(np.min(d[:, iu[0], iu[1]])), 2),
        "dv_mps": np.round(run.delta_v_mps, 3).tolist(),
    }


DOCK_M = hexagon_vertices(SIDE_M, 30.0)[0]  # the 30-degree vertex (0, 8.66, 5) m
FAST_DT_S = 5.0  # the default tests; outcomes checked equal to 1 s steps for these cases (docs/paper001.md)


def check_timeline_and_limits(run: Run) -> dict:
    """What holds in every run of the paper's scenario, hexagon or not."""
    s = summary(run)
    t_mid, t_in = np.array(s["t_middle_s"]), np.array(s["t_inner_s"])
    assert np.all((t_mid > 16000.0) & (t_mid <= 0.975 * 1.95e4 + FAST_DT_S)), t_mid  # paper: ~16880 s
    assert np.all(np.isfinite(t_in[np.linalg.norm(run.pos_m[-1], axis=1) < 15.0]))
    a = np.linalg.norm(run.acc_mps2, axis=2)
    assert a.max() <= 5e-3 * (1 + 1e-12)  # thrust within u_max by norm
    # at release |u| = min(k_g |v_d|, u_max): |v_d| is 0.011 m/s (from +-z) to 0.136 m/s, so the agents that
    # need more than 0.1 m/s saturate for up to ~30 s (Fig. 4a); by 200 s all ride their ballistic arcs
    assert np.any(a[0] >= 5e-3 * (1 - 1e-9)) and np.all(a[int(200 / run.dt_s)] < 1e-4)
    cruise = a[int(1000 / run.dt_s): int(15000 / run.dt_s)]
    assert cruise.max() < 1e-6  # on the ballistic arcs the far field asks for nothing
    assert s["v_max_mps"] < 0.18  # paper: speeds below 0.18 m/s
    assert s["d_min_m"] > 5.0  # no collision: TB repulsion keeps pairs apart
    return s


def test_paper_reading_seed1_forms_the_hexagon_centred_on_the_dock_vertex() -> None:
    """Paper's reading (cutoffs / 1.315, eq. 14 in m/s^2, dock well = g_free's width at the 30-degree vertex,
    no g_free in the shaping ball), release directions of seed 1: a regular hexagon of side 10.04 m forms in
    the yz-plane by ~22,200 s, but centred on the dock vertex, not the origin, with a free phase."""
    run = simulate(sphere_directions(1), 32000.0, dt_s=FAST_DT_S, record_every=2)
    s = check_timeline_and_limits(run)
    hx = check_hexagon(run.pos_m[-1], SIDE_M)
    assert s["structure"] == "6-ring" and hx.is_hexagon
    assert 10.0 < hx.side_min_m <= hx.side_max_m < 10.1  # TB relaxed side 10.40 m, compressed by the wells
    assert 119.0 < hx.angle_min_deg <= hx.angle_max_deg < 121.0
    assert hx.thickness_m < 0.05 and hx.normal_x > 0.9999  # in a plane parallel to yz
    assert abs(run.pos_m[-1][:, 0]).max() < 0.05  # ... and that plane is x = x_shift = 0
    assert np.linalg.norm(hx.centre_m - DOCK_M) < 0.1  # the wide dock well centres the ring on its vertex
    assert hx.eq16 < 0.0125  # paper: 0.0125
    assert 20000.0 < s["t_form_s"] < 25000.0  # paper: less than 25,000 s
    assert np.all(run.delta_v_mps < 3.0)
    assert claim_failures("p001.paper-1-5s", run) == []  # docs/paper001.md's "(5 s)" figure (claims/check.py)


def test_paper_reading_octahedral_release_is_trapped_in_a_branched_tree() -> None:
    """Released from the six octahedron vertices (+-x, +-y, +-z) the swarm arrives in three pairs; the TB bonds
    close into a planar branched tree (a local minimum: chain ends rest beyond the cutoff), not a hexagon."""
    run = simulate(sphere_directions(None), 26000.0, dt_s=FAST_DT_S, record_every=2)
    s = check_timeline_and_limits(run)
    assert s["structure"] == "branched tree" and not s["hexagon"]
    assert s["thickness_m"] < 0.05  # planar all the same


READINGS = {
    "paper": {},  # Table 3 as printed; dock well alpha_ph = alpha_f, k_ph = k_f at the 30-degree vertex
    "centred": {"free_in_shaping": True, "k_phase_m2": 25.0},  # g_free kept in the ball, 5 m dock well
    "literal": {"cutoff_reading": "literal"},  # R(1), R(2) as printed (angstrom values)
    "ae": {"tb_unit": "a_e"},  # eq. 14 read in units of a_e
}
# measured with 1 s steps (docs/paper001.md): release -> structure at 32,000 s
MEASURED = {
    "paper": {"oct": "branched tree", 0: "5-ring+1", 1: "6-ring", 2: "6-ring", 3: "6-ring", 4: "6-ring",
              5: "3-D 3-ring+3", 6: "6-ring", 7: "6-ring", 8: "3-D 3-ring+3", 9: "branched tree"},
    "centred": {"oct": "branched tree", 0: "3-D 3-ring+3", 1: "4-ring+2", 2: "6-ring", 3: "5-ring+1", 4: "6-ring",
                5: "branched tree", 6: "5-ring+1", 7: "5-ring+1", 8: "3-D multi-ring", 9: "branched tree"},
    "literal": {"oct": "3-D fragments", 1: "3-D 6-ring", 2: "6-ring", 3: "3-D chain"},
    "ae": {"oct": "multi-ring", 1: "3-D multi-ring", 2: "3-D multi-ring", 3: "multi-ring"},
}


CI_CASES = {("paper", 1), ("paper", "oct"), ("literal", 2)}  # the hexagon, the trap, the literal cutoffs


@pytest.mark.system
@pytest.mark.parametrize("reading,seed", [pytest.param(r, s, marks=() if (r, s) in CI_CASES else pytest.mark.study)
                                          for r in MEASURED for s in MEASURED[r]])
def test_release_to_structure_at_1s_steps(reading: str, seed) -> None:
    """The success-rate study, one release per test: timeline, limits and the structure that formed."""
    run = simulate(sphere_directions(None if seed == "oct" else seed), 32000.0, dt_s=1.0,
                   params=READINGS[reading], record_every=10)
    s = check_timeline_and_limits(run)
    assert s["structure"] == MEASURED[reading][seed]
    source = f"p001.{reading}-{seed}"
    assert source in registry().sources  # every release is a source (claims/paper001.py, paper001_study.py)
    assert claim_failures(source, run) == []  # its docs/paper001.md row (claims/check.py)
    if s["structure"] == "6-ring" and reading in ("paper", "centred"):
        hx = check_hexagon(run.pos_m[-1], SIDE_M)
        assert hx.is_hexagon and hx.thickness_m < 0.05 and s["t_form_s"] < 25000.0
        centre = DOCK_M if reading == "paper" else np.zeros(3)
        assert np.linalg.norm(hx.centre_m - centre) < 0.1
        if reading == "centred":
            assert abs(hx.phase_deg - 30.0) < 2.0  # the 5 m dock well sets the paper's 30-degree phase


if __name__ == "__main__":  # python tests/missions/test_p001_closed_loop.py [seed|oct] [duration] [k=v ...]
    import sys
    import time

    arg = sys.argv[1] if len(sys.argv) > 1 else "oct"
    dur = float(sys.argv[2]) if len(sys.argv) > 2 else 40000.0
    kw: dict = {}
    for a in sys.argv[3:]:
        k, v = a.split("=")
        try:
            kw[k] = float(v)
        except ValueError:
            kw[k] = {"True": True, "False": False}.get(v, v)
    t0 = time.time()
    r = simulate(sphere_directions(None if arg == "oct" else int(arg)), dur, params=kw, record_every=10)
    print(f"wall {time.time() - t0:.1f}s")
    for k, v in summary(r).items():
        print(k, v)
