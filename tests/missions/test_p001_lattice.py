"""Paper 001 room, unit level: TB energy and exact forces, far-layer field, wells, layers, eq. 16."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import minimize_scalar

from swarmhil.agent.catalogue import known_controllers, make_controller
from swarmhil.agent.controller import Observation, OrbitInfo
from swarmhil.missions.p001_lattice.fsw.cw import ballistic_velocity, far_accel
from swarmhil.missions.p001_lattice.contract import check_hexagon, hexagon_vertices, mean_relative_error
from swarmhil.missions.p001_lattice.fsw.layers import Layer, next_layer
from swarmhil.missions.p001_lattice.contract import LatticeParams
from swarmhil.missions.p001_lattice.fsw.sensing import OwnState
from swarmhil.missions.p001_lattice.fsw.tersoff import energy, forces, gradient, tersoff_params
from swarmhil.missions.p001_lattice.contract import A_E_MPS2, TB_GAIN
from swarmhil.missions.p001_lattice.fsw.wells import planar_well, point_well, saturate

N_GEO = 7.2921e-5
READINGS = ["normalised", "literal"]


def fd_gradient(pos: np.ndarray, p, h: float = 1e-6) -> np.ndarray:
    g = np.zeros_like(pos)
    for i in range(pos.shape[0]):
        for k in range(3):
            xp, xm = pos.copy(), pos.copy()
            xp[i, k] += h
            xm[i, k] -= h
            g[i, k] = (energy(xp, p) - energy(xm, p)) / (2 * h)
    return g


def configs() -> list[np.ndarray]:
    """Random clusters where every cutoff branch is hit, a triangle, a pentagon plus one, a strained hexagon."""
    rng = np.random.default_rng(7)
    out = [rng.uniform(-1.1, 1.1, (n, 3)) for n in (3, 5, 6, 7)]
    pent = np.column_stack([np.zeros(5), np.cos(np.arange(5) * 1.2566), np.sin(np.arange(5) * 1.2566)]) * 0.9
    out.append(np.vstack([pent, [[0.1, 1.95, 0.2]]]))
    out.append(hexagon_vertices(1.0) * 1.1 + rng.normal(scale=0.05, size=(6, 3)))
    return out


def hessian(x: np.ndarray, p, h: float = 1e-5) -> np.ndarray:
    n = x.size
    hm = np.zeros((n, n))
    for a in range(n):
        xp, xm = x.ravel().copy(), x.ravel().copy()
        xp[a] += h
        xm[a] -= h
        hm[:, a] = (gradient(xp.reshape(-1, 3), p) - gradient(xm.reshape(-1, 3), p)).ravel() / (2 * h)
    return 0.5 * (hm + hm.T)


@pytest.mark.parametrize("reading", READINGS)
def test_tb_forces_are_the_exact_negative_gradient(reading: str) -> None:
    p = tersoff_params(reading)
    d = np.concatenate([np.linalg.norm(x[:, None] - x[None], axis=2)[np.triu_indices(len(x), 1)] for x in configs()])
    assert np.sum((d > p.r1) & (d < p.r2)) >= 3, "the cutoff's switching region was not exercised"
    for pos in configs():
        g = gradient(pos, p)
        fd = fd_gradient(pos, p)
        # central differences with h = 1e-6 on energies of order 1: error ~1e-9
        assert np.max(np.abs(g - fd)) < 1e-7 * max(1.0, np.max(np.abs(g))), (reading, np.max(np.abs(g - fd)))
        assert np.allclose(forces(pos, p), -g)


@pytest.mark.parametrize("reading", READINGS)
def test_tb_forces_obey_newtons_third_law_and_carry_no_torque(reading: str) -> None:
    p = tersoff_params(reading)
    for pos in configs():
        f = forces(pos, p)
        assert np.max(np.abs(f.sum(axis=0))) < 1e-12 * max(1.0, np.abs(f).max()) * len(pos)
        torque = np.cross(pos - pos.mean(axis=0), f).sum(axis=0)
        assert np.max(np.abs(torque)) < 1e-11 * max(1.0, np.abs(f).max())


def test_hexagon_is_a_stable_equilibrium_with_normalised_cutoffs_at_side_1_0404_l() -> None:
    """Cutoffs / 1.315: only nearest neighbours bond; B_ij(120 deg) < 1 stretches the bond to 1.0404 l."""
    p = tersoff_params("normalised")
    assert p.r2 < np.sqrt(3.0)  # second neighbours (sqrt(3) l) never interact
    hexa = hexagon_vertices(1.0)
    side = minimize_scalar(lambda s: energy(hexa * s, p), bounds=(0.8, 1.3), method="bounded", options={"xatol": 1e-10}).x
    assert side == pytest.approx(1.0404, abs=2e-4)
    assert np.max(np.abs(forces(hexa * side, p))) < 1e-5
    ev = np.linalg.eigvalsh(hessian(hexa * side, p))
    assert np.all(np.abs(ev[:6]) < 1e-4) and ev[6] > 1.0  # six rigid-body modes, the rest stiff
    # at side l exactly the bonds are compressed: every force points radially outwards
    f = forces(hexa, p)
    assert np.all(np.einsum("ij,ij->i", f, hexa) > 0.3)
    assert mean_relative_error(hexa * side * 10.0, 10.0) == pytest.approx(0.0404, abs=2e-4)


def test_hexagon_of_side_l_is_not_an_equilibrium_with_literal_cutoffs() -> None:
    """Cutoffs read as printed (1.95 l, 2.25 l): second neighbours and opposite vertices interact."""
    p = tersoff_params("literal")
    hexa = hexagon_vertices(1.0)
    assert np.max(np.linalg.norm(forces(hexa, p), axis=1)) > 4.0  # ~4.6: 4.6e-3 m/s^2 in the m/s^2 reading
    side = minimize_scalar(lambda s: energy(hexa * s, p), bounds=(0.8, 1.6), method="bounded", options={"xatol": 1e-10}).x
    assert side == pytest.approx(1.288, abs=2e-3)  # relaxes to 12.9 m, second neighbours then at 22.3 m > r_Z
    assert side * np.sqrt(3.0) * 10.0 > 21.0


def cw_stm(n: float, t: float) -> np.ndarray:
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0], a[3, 4], a[4, 3], a[5, 2] = 3 * n * n, 2 * n, -2 * n, -n * n
    return expm(a * t)


def test_far_layer_field_flies_an_uncontrolled_cw_state_to_the_origin_at_t_desire() -> None:
    rng = np.random.default_rng(3)
    t_desire = 1.95e4
    for _ in range(5):
        r0 = rng.normal(size=3)
        r0 *= 1000.0 / np.linalg.norm(r0)
        t0 = rng.uniform(0.0, 1.5e4)
        v0 = ballistic_velocity(r0, N_GEO, t_desire - t0)
        end = cw_stm(N_GEO, t_desire - t0) @ np.concatenate([r0, v0])
        assert np.linalg.norm(end[:3]) < 1e-6  # metres, from 1000 m
        # on the arc the field asks for nothing: g_far = 0 at every later point of it
        mid = cw_stm(N_GEO, 0.5 * (t_desire - t0)) @ np.concatenate([r0, v0])
        assert np.linalg.norm(far_accel(mid[:3], mid[3:], N_GEO, 0.5 * (t_desire - t0), 0.05)) < 1e-12
    with pytest.raises(ValueError):
        ballistic_velocity(r0, N_GEO, 0.0)


def test_eq16_of_known_configurations_and_the_geometric_hexagon_test() -> None:
    hexa = hexagon_vertices(10.0)
    assert mean_relative_error(hexa, 10.0) == pytest.approx(0.0, abs=1e-12)
    assert mean_relative_error(hexa * 1.1, 10.0) == pytest.approx(0.1)
    chk = check_hexagon(hexa, 10.0)
    assert chk.is_hexagon and chk.ring and chk.phase_deg == pytest.approx(30.0) and chk.normal_x == pytest.approx(1.0)
    assert np.allclose(chk.centre_m, 0.0, atol=1e-12)
    # trap 2: a compact 3-D cluster (octahedron of edge l) has a low eq. 16 but is no hexagon
    octa = np.vstack([np.eye(3), -np.eye(3)]) * 10.0 / np.sqrt(2.0)
    assert mean_relative_error(octa, 10.0) < 0.02
    assert not check_hexagon(octa, 10.0).is_hexagon
    # trap 1: a pentagon with one dangling agent
    ang = np.deg2rad(72.0 * np.arange(5))
    r5 = 10.0 / (2 * np.sin(np.pi / 5))
    pent = np.column_stack([np.zeros(5), r5 * np.cos(ang), r5 * np.sin(ang)])
    pent1 = np.vstack([pent, [0.0, r5 + 10.0, 0.0]])
    assert not check_hexagon(pent1, 10.0).is_hexagon


def test_wells_layers_and_saturation() -> None:
    p = LatticeParams()
    assert np.sqrt(p.k_free_m2) == pytest.approx(127.3, abs=0.1)
    assert p.alpha_free_ps2 == pytest.approx(2.748e-5, rel=1e-3)
    assert p.damping_ps == pytest.approx(1.752e-2, rel=1e-3)
    g = point_well(np.array([10.0, 0, 0]), np.zeros(3), p.alpha_free_ps2, p.k_free_m2)
    assert g[0] < 0 and g[1] == 0 == g[2]
    assert planar_well(np.array([3.0, 50.0, -40.0]), 0.0, 1.0, 1e4)[1:].tolist() == [0.0, 0.0]
    a = saturate(np.array([3e-3, 4e-3, 12e-3]), 5e-3)
    assert np.linalg.norm(a) == pytest.approx(5e-3) and np.allclose(a / np.linalg.norm(a), np.array([3, 4, 12]) / 13)
    assert next_layer(Layer.FAR, 500.0, 100.0, 100.0, 15.0, 19012.5) == Layer.FAR
    assert next_layer(Layer.FAR, 500.0, 19013.0, 100.0, 15.0, 19012.5) == Layer.NEAR
    assert next_layer(Layer.FAR, 99.0, 100.0, 100.0, 15.0, 19012.5) == Layer.NEAR
    assert next_layer(Layer.SHAPING, 500.0, 100.0, 100.0, 15.0, 19012.5) == Layer.SHAPING  # latched
    assert next_layer(Layer.NEAR, 14.0, 100.0, 100.0, 15.0, 19012.5) == Layer.SHAPING
    with pytest.raises(ValueError, match="unknown p001-lattice parameters"):
        LatticeParams.from_dict({"cutof_reading": "literal"})
    with pytest.raises(ValueError, match="true or false"):
        LatticeParams.from_dict({"free_in_shaping": "False"})
    assert LatticeParams.from_dict({"free_in_shaping": True, "k_phase_m2": 25}).k_phase_m2 == 25.0
    with pytest.raises(ValueError, match="tb_unit"):
        LatticeParams.from_dict({"tb_unit": "N"})


def test_controller_is_registered_and_speaks_si() -> None:
    assert "p001-lattice" in known_controllers()
    orbit = OrbitInfo(semi_major_axis_m=42164e3, mean_motion_radps=N_GEO)
    c = make_controller("p001-lattice", "a", orbit, {})
    own = OwnState(np.array([1000.0, 0.0, 0.0]), np.zeros(3))
    obs = Observation(step=0, t_s=0.0, u_rad=0.0, neighbour_ids=[], rel_position_m=np.zeros((0, 3)),
                      rel_velocity_mps=np.zeros((0, 3)), extra=own.to_extra())
    cmd = c.step(obs)
    assert cmd.mode == "far" and np.linalg.norm(cmd.accel_mps2) == pytest.approx(5e-3)  # saturated at release
    with pytest.raises(KeyError, match="own_position_m"):
        c.step(Observation(step=1, t_s=1.0, u_rad=0.0, neighbour_ids=[], rel_position_m=np.zeros((0, 3)),
                           rel_velocity_mps=np.zeros((0, 3))))
    # in the shaping ball, one neighbour 12 m away along +z attracts, 5 m away repels; eq. 14 scale
    for unit, scale in (("mps2", 1.0), ("a_e", A_E_MPS2)):
        c = make_controller("p001-lattice", "a", orbit, {"tb_unit": unit, "alpha_phase_ps2": 0.0,
                                                          "alpha_planar_ps2": 0.0, "damping_ps": 0.0})
        ex = OwnState(np.zeros(3), np.zeros(3)).to_extra()
        far = c.step(Observation(0, 0.0, 0.0, ["b"], np.array([[0, 0, 12.0]]), np.zeros((1, 3)), ex)).accel_mps2
        near = c.step(Observation(1, 1.0, 0.0, ["b"], np.array([[0, 0, 5.0]]), np.zeros((1, 3)), ex)).accel_mps2
        assert far[2] > 0 and near[2] < 0
        f = forces(np.array([[0, 0, 0], [0, 0, 1.2]]), tersoff_params())[0]
        assert far == pytest.approx(TB_GAIN * scale * f)
    r = OwnState.from_extra(OwnState(np.array([1.0, 2, 3]), np.array([4.0, 5, 6])).to_extra())
    assert r.position_m.tolist() == [1, 2, 3] and r.velocity_mps.tolist() == [4, 5, 6]


def test_the_room_never_imports_plant_or_bus() -> None:
    import ast
    from pathlib import Path

    room = Path(__file__).resolve().parents[2] / "agent" / "missions" / "p001_lattice"
    for path in room.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in ("plant", "bus") for n in names), (path.name, names)


@pytest.mark.parametrize("params", [{}, {"far_damping": True, "free_in_shaping": True}], ids=["default", "damped"])
def test_step_batch_is_each_step_bit_for_bit(params: dict) -> None:
    """LatticeController.step_batch (issue 29: the batch run's path) gives each spacecraft its own
    `step`'s command, byte for byte, and leaves it in the same layer: random swarms of six over
    hundreds of steps with spacecraft in every layer (far, near, shaping), neighbours in and out of
    the 21 m ball (the Tersoff-Brenner term), times before and after t_natural."""
    import copy

    from swarmhil.agent.controller import Observation, ObservationBatch, OrbitInfo
    from swarmhil.bus.codec import NamedRows
    from swarmhil.missions.p001_lattice.fsw.sensing import OWN_POSITION_KEY, OWN_VELOCITY_KEY

    orbit = OrbitInfo(42164230.752852604, 7.2921e-5)
    rng = np.random.default_rng(29)
    ids = [f"sc{i}" for i in range(6)]
    one = [make_controller("p001-lattice", s, orbit, params) for s in ids]
    many, arrays = copy.deepcopy(one), copy.deepcopy(one)
    layers = set()
    for k in range(300):
        scale = rng.choice([8.0, 40.0, 300.0])
        pos, vel = rng.normal(0, scale, (6, 3)), rng.normal(0, 0.05, (6, 3))
        t = float(rng.choice([5.0 * k, 19000.0 + k]))
        obs = []
        for i in range(6):
            near = [j for j in range(6) if j != i and np.linalg.norm(pos[j] - pos[i]) <= 21.0]
            obs.append(Observation(step=k, t_s=t, u_rad=0.0, neighbour_ids=[ids[j] for j in near],
                                   rel_position_m=(pos[near] - pos[i]).reshape(-1, 3),
                                   rel_velocity_mps=(vel[near] - vel[i]).reshape(-1, 3),
                                   extra={OWN_POSITION_KEY: pos[i], OWN_VELOCITY_KEY: vel[i]}))
        want = [c.step(o) for c, o in zip(one, obs)]
        got = type(many[0]).step_batch(many, ObservationBatch.of(ids, obs))
        assert got.accel_mps2.tobytes() == np.array([w.accel_mps2 for w in want]).tobytes()
        assert got.modes == [w.mode for w in want] and [c.layer for c in many] == [c.layer for c in one]
        # the own states as the batch sensing gives them: two arrays (bus/codec.py NamedRows)
        rows = ObservationBatch.of(ids, obs)
        rows.extra = NamedRows({OWN_POSITION_KEY: pos + 0.0, OWN_VELOCITY_KEY: vel + 0.0}, 6)
        got = type(arrays[0]).step_batch(arrays, rows)
        assert got.accel_mps2.tobytes() == np.array([w.accel_mps2 for w in want]).tobytes()
        assert got.finite and np.isfinite(got.accel_mps2).all()  # (BatchAgents then skips its own finite test)
        assert got.modes == [w.mode for w in want] and [c.layer for c in arrays] == [c.layer for c in one]
        layers |= set(got.modes)
        if k % 50 == 49:  # start over: the layers latch inwards
            one = [make_controller("p001-lattice", s, orbit, params) for s in ids]
            many, arrays = copy.deepcopy(one), copy.deepcopy(one)
    assert layers == {"far", "near", "shaping"}


def _awkward(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Random float64 with -0.0, subnormals, tiny and huge magnitudes mixed in."""
    a = rng.normal(0, 1, shape) * 10.0 ** rng.integers(-12, 12, shape)
    flat = a.reshape(-1)
    pick = rng.integers(0, flat.size, max(1, flat.size // 5))
    flat[pick] = rng.choice(np.array([-0.0, 0.0, 5e-324, -2.2e-308, 1e300]), len(pick))
    return a


def test_cw_position_blocks_are_the_array_built_ones_byte_for_byte() -> None:
    """cw.cw_position_blocks (entries as Python floats, issue 29) equals the nested-array form it
    replaced, byte for byte, over times to go of every sign and size."""
    from swarmhil.missions.p001_lattice.fsw.cw import cw_position_blocks

    def before(n_radps: float, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        tau = n_radps * t_s
        s, c = np.sin(tau), np.cos(tau)
        phi_rr = np.array([[4.0 - 3.0 * c, 0.0, 0.0], [6.0 * (s - tau), 1.0, 0.0], [0.0, 0.0, c]])
        phi_rv = np.array([[s, 2.0 * (1.0 - c), 0.0], [-2.0 * (1.0 - c), 4.0 * s - 3.0 * tau, 0.0],
                           [0.0, 0.0, s]]) / n_radps
        return phi_rr, phi_rv

    rng = np.random.default_rng(291)
    times = np.concatenate([rng.uniform(-1e5, 1e5, 300), 10.0 ** rng.uniform(-9, 9, 300), [0.0, -0.0, 5e-324, 1e-300]])
    for n in (N_GEO, 1.1e-3, float(rng.uniform(1e-6, 1e-2))):
        for t in times.tolist():
            for a, b in zip(cw_position_blocks(n, t), before(n, t)):
                assert a.shape == b.shape == (3, 3) and a.dtype == b.dtype and a.tobytes() == b.tobytes(), (n, t)
        for a, b in zip(cw_position_blocks(np.float64(n), np.float64(1234.5)), before(np.float64(n), np.float64(1234.5))):
            assert a.tobytes() == b.tobytes()


def test_solve_each_and_row_dots_are_numpys_own_calls_byte_for_byte() -> None:
    """cw.solve_each equals np.linalg.solve of each system by itself (the per-agent `step`'s call,
    a 1-D right-hand side) and agent.rowwise.row_dots equals each row's `dot` (np.linalg.norm's
    square), byte for byte, NaN, ±inf, -0.0 and subnormals included in the rows."""
    from swarmhil.agent.rowwise import row_dots
    from swarmhil.missions.p001_lattice.fsw.cw import solve_each

    rng = np.random.default_rng(292)
    with np.errstate(over="ignore", invalid="ignore"):  # (the huge rows' squares overflow, in both)
        _solve_and_dot_cases(rng, row_dots, solve_each)


def test_solve_each_without_numpys_private_gufunc_is_the_same_call(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where numpy has no `_umath_linalg.solve1` (a private name), solve_each solves row by row
    with np.linalg.solve: the same bytes."""
    from swarmhil.missions.p001_lattice.fsw import cw
    from swarmhil.agent.rowwise import row_dots

    monkeypatch.setattr(cw, "_SOLVE1", None)
    rng = np.random.default_rng(293)
    with np.errstate(over="ignore", invalid="ignore"):
        _solve_and_dot_cases(rng, row_dots, cw.solve_each)


def _solve_and_dot_cases(rng: np.random.Generator, row_dots, solve_each) -> None:  # noqa: ANN001
    from swarmhil.missions.p001_lattice.fsw.cw import cw_position_blocks, matvec_rows

    for _ in range(200):
        k = int(rng.integers(1, 9))
        _rr, phi_rv = cw_position_blocks(N_GEO, float(rng.uniform(10.0, 40000.0)))
        rhs = rng.normal(0, 1e3, (k, 3))
        got = solve_each(phi_rv, rhs)
        assert got.shape == (k, 3)
        prod = matvec_rows(phi_rv, rhs)
        assert prod.tobytes() == np.matmul(phi_rv, rhs[:, :, None])[:, :, 0].tobytes()  # (the numpy 1 route)
        for i in range(k):
            assert got[i].tobytes() == np.linalg.solve(phi_rv, rhs[i]).tobytes()
            assert prod[i].tobytes() == (phi_rv @ rhs[i]).tobytes()
        a = _awkward(rng, (k, 3))
        a[rng.integers(0, k)] = rng.choice(np.array([np.nan, np.inf, -np.inf, 1.0]), 3)
        d = row_dots(a)
        assert d.shape == (k,)
        assert d.tobytes() == np.matmul(a[:, None, :], a[:, :, None]).reshape(k).tobytes()  # (the numpy 1 route)
        for i in range(k):
            assert d[i].tobytes() == np.float64(a[i].dot(a[i])).tobytes()
            if np.isfinite(a[i]).all():
                assert np.sqrt(d[i]).tobytes() == np.float64(np.linalg.norm(a[i])).tobytes()


def test_a_non_finite_own_state_leaves_the_batch_as_each_step_would() -> None:
    """A NaN or ±inf in one spacecraft's own position or velocity (any layer, before and after
    t_natural): the batch agents (agent/batch.py, the sensing's arrays) command what each `step`
    commands (zero where it raises, the fault counted) and every layer stays as each `step` leaves it."""
    import copy

    from swarmhil.agent.batch import BatchAgents
    from swarmhil.agent.controller import Observation, ObservationBatch, OrbitInfo
    from swarmhil.bus.codec import NamedRows
    from swarmhil.missions.p001_lattice.fsw.sensing import OWN_POSITION_KEY, OWN_VELOCITY_KEY

    orbit = OrbitInfo(42164230.752852604, 7.2921e-5)
    rng = np.random.default_rng(30)
    ids = [f"sc{i}" for i in range(6)]
    for case in range(120):
        agents = BatchAgents(ids, [("p001-lattice", {})] * 6, orbit)
        for c, layer in zip(agents.controllers, rng.choice([Layer.FAR, Layer.NEAR, Layer.SHAPING], 6)):
            c.layer = Layer(int(layer)) if case % 3 else Layer.FAR
        one = copy.deepcopy(agents.controllers)
        pos, vel = rng.normal(0, float(rng.choice([8.0, 300.0])), (6, 3)), rng.normal(0, 0.05, (6, 3))
        (pos if case % 2 else vel)[int(rng.integers(0, 6)), int(rng.integers(0, 3))] = rng.choice([np.nan, np.inf, -np.inf])
        t = float(rng.choice([50.0, 19100.0]))  # (t_natural 19012.5 s)
        want, faults = [], set()
        for i, c in enumerate(one):
            try:
                want.append(c.step(Observation(step=1, t_s=t, u_rad=0.0, neighbour_ids=[], rel_position_m=np.zeros((0, 3)),
                                               rel_velocity_mps=np.zeros((0, 3)),
                                               extra={OWN_POSITION_KEY: pos[i] + 0.0, OWN_VELOCITY_KEY: vel[i] + 0.0})).accel_mps2)
            except (ValueError, np.linalg.LinAlgError):
                want.append(np.zeros(3))
                faults.add(ids[i])
        batch = ObservationBatch(step=1, t_s=t, u_rad=0.0, observers=ids, offsets=np.zeros(7, dtype=np.int64),
                                 neighbour_ids=[], rel_position_m=np.zeros((0, 3)), rel_velocity_mps=np.zeros((0, 3)),
                                 extra=NamedRows({OWN_POSITION_KEY: pos + 0.0, OWN_VELOCITY_KEY: vel + 0.0}, 6))
        got = agents.step(np.arange(6), batch)
        assert got.tobytes() == np.array(want).tobytes(), case
        assert [c.layer for c in agents.controllers] == [c.layer for c in one], case
        assert set(agents.faults) == faults, case
