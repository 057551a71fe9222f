"""The neighbour search of large swarms (plant/sensors.py `visible_pairs`, `pairs_within`): the pairs a
k-d tree finds are the brute-force (N, N) rule's, exactly, on random swarms, with pairs tied exactly
at the detection range and at the field-of-view edges, dead observers, coincident spacecraft; and the
plant's users of it (the `rel` and `scene` stimuli, contact) give what their (N, N) forms give."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.plant.sensors import (CameraGeometry, pairs_within, visibility_matrix, visible_pairs, weakly_connected,
                                    weakly_connected_pairs)

# tan of the half FOV = 500 / 1000 = 0.5 exactly, and a range of 13 * 40 m: the 3-4-12-13 offsets
# (3, 12, 4) * 40 are at the range exactly (|r|^2 = 520^2 in float64) and inside the FOV, and
# (6, 12, 0) * k, (0, 12, 6) * k are on its edges (|x| = 0.5 y exactly).
CAM = CameraGeometry(detection_range_m=520.0, image_px=1000, focal_px=1000.0)
TIES = np.array([[120.0, 480.0, 160.0], [-120.0, 480.0, -160.0], [0.0, 520.0, 0.0], [120.0, 240.0, 0.0],
                 [0.0, 240.0, -120.0], [-60.0, 120.0, 60.0], [60.0, 120.0, -60.0], [0.0, 0.0, 520.0],
                 [0.0, 520.0, 1e-3], [0.0, 520.0000000000001, 0.0]])


def _brute(pos: np.ndarray, cam: CameraGeometry, alive: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    return visibility_matrix(pos, cam, alive).nonzero()


def _swarm(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random swarm on a 20 m grid (many exact ties of distance), each spacecraft with a chance of a
    companion at a tie offset (range or FOV edge) from it, and a few coincident pairs."""
    pos = rng.integers(-60, 60, size=(n, 3)).astype(float) * 20.0
    pos[:, 1] *= float(rng.choice([1.0, 4.0]))  # along-track spread like the paper's chains
    for i in range(0, n - 1, 3):
        pos[i + 1] = pos[i] + TIES[rng.integers(len(TIES))] * rng.choice([1.0, -1.0])
    if n > 4:
        pos[4] = pos[0]  # coincident
    return pos


@pytest.mark.parametrize("seed", range(6))
def test_tree_pairs_equal_the_brute_force_rule(seed: int) -> None:
    rng = np.random.default_rng(seed)
    ties = seen = 0
    for case in range(40):
        n = int(rng.integers(2, 400))
        pos = _swarm(rng, n)
        alive = None if case % 3 else rng.random(n) < 0.8
        for cam in (CAM, CameraGeometry()):
            want = _brute(pos, cam, alive)
            got = visible_pairs(pos, cam, alive, tree=True)
            assert got[0].dtype == np.int64 or len(got[0]) == 0
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), (seed, case, n)
            auto = visible_pairs(pos, cam, alive)  # (the matrix below TREE_MIN_COUNT, the tree above)
            assert np.array_equal(auto[0], want[0]) and np.array_equal(auto[1], want[1])
            seen += len(want[0])
            rel = pos[want[1]] - pos[want[0]]
            ties += int(np.count_nonzero(np.einsum("ij,ij->i", rel, rel) == cam.detection_range_m**2))
            ties += int(np.count_nonzero(np.abs(rel[:, 0]) == cam.tan_half_fov * rel[:, 1]))
            m = visibility_matrix(pos, cam, alive)
            assert weakly_connected_pairs(n, *got) == weakly_connected(m)
    assert seen > 2000 and ties > 100  # the swarms see each other, many pairs exactly on an edge


def test_the_ties_themselves() -> None:
    """Each tie offset from an observer at the origin: the matrix's verdict, and the tree agrees."""
    pos = np.vstack([np.zeros(3), TIES])
    want = visibility_matrix(pos, CAM)[0]
    assert want[1:8].all() and not want[8] and not want[9] and not want[10]  # on the edges: seen; past: not
    j, k = visible_pairs(pos, CAM, tree=True)
    assert np.array_equal(np.sort(k[j == 0]), np.flatnonzero(want))


def test_non_finite_positions_take_the_matrix() -> None:
    pos = _swarm(np.random.default_rng(3), 100)
    pos[7, 0] = np.nan
    pos[9, 2] = np.inf
    with np.errstate(invalid="ignore"):
        got, want = visible_pairs(pos, CAM, tree=True), _brute(pos, CAM, None)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]) and len(want[0]) > 20


def test_pairs_within_holds_every_pair_in_range() -> None:
    rng = np.random.default_rng(5)
    pos = rng.integers(-40, 40, size=(300, 3)).astype(float) * 5.0
    a, b = pairs_within(pos, 40.0)
    d2 = ((pos[:, None, :] - pos[None, :, :]) ** 2).sum(axis=2)
    ia, ib = np.nonzero(np.triu(d2 <= 40.0**2, 1))
    assert set(zip(ia.tolist(), ib.tolist())) <= set(zip(a.tolist(), b.tolist())) and len(ia) > 100
    assert (a < b).all() and len(pairs_within(pos[:1], 25.0)[0]) == 0


@pytest.mark.parametrize("bias", [[0.0, 0.0, 0.0], [1e-3, -2e-3, 5e-4]])
def test_scene_batch_by_tree_is_the_matrix_form_byte_for_byte(monkeypatch: pytest.MonkeyPatch, bias: list[float]) -> None:
    """plant/scene_stimulus.py: every observer's scene of a large swarm from the tree's pairs equals the
    (R, N) form's, every array byte for byte, all observers and a subset of them (with a pointing error
    the (R, N) form is kept: a general rotation's product is BLAS's, whose last bits may depend on the
    number of rows)."""
    from conftest import SCENARIOS
    from swarmhil.deploy.scenario import load_scenario, plant_config
    from swarmhil.plant import scene_stimulus

    sc = load_scenario(SCENARIOS / "sabatini-20-camera-exact.toml", [f"sensing.pointing_error_rad={bias}"])
    builder = scene_stimulus.SceneStimulusBuilder(plant_config(sc))
    rng = np.random.default_rng(36)
    bodies = 0
    for case in range(12):
        n = int(rng.integers(64, 300))
        builder.ids = [f"s{i}" for i in range(n)]
        pos = _swarm(rng, n) / 2.0 + rng.normal(size=(n, 3)) * (case % 2)
        obs = np.arange(n) if case % 3 else np.sort(rng.choice(n, n // 2, replace=False))
        monkeypatch.setattr(scene_stimulus, "TREE_MIN_COUNT", 10**9)
        want = builder.batch(obs, pos)
        monkeypatch.setattr(scene_stimulus, "TREE_MIN_COUNT", 64)
        got = builder.batch(obs, pos)
        for f in ("offsets", "neighbour", "position_cam_m", "attitude_wxyz", "pointing_error_rad"):
            x, y = getattr(got, f), getattr(want, f)
            assert x.shape == y.shape and x.tobytes() == y.tobytes(), (case, f)
        bodies += len(want.neighbour)
    assert bodies > 1000


def test_contact_pairs_of_a_large_swarm_are_the_matrix_ones(monkeypatch: pytest.MonkeyPatch) -> None:
    """plant/contact.py ContactMonitor: the contacts and near misses it finds in a large swarm from the
    tree's close pairs (CloseCentres) are those of the (N, N) matrices, step by step, with pairs exactly
    at a reach (r_a + r_b: not in contact) and coincident ones."""
    from swarmhil.plant import contact
    from swarmhil.plant.contact import ContactConfig, ContactMonitor

    rng = np.random.default_rng(27)
    found = 0
    for case in range(20):
        n = int(rng.integers(64, 250))
        ids = [f"s{i}" for i in range(n)]
        radius = rng.choice([0.5, 0.25, 1.0], size=n)
        cfg = ContactConfig(keep_out_m=float(rng.choice([0.0, 2.0])))
        mons = [ContactMonitor(ids, radius, [], {}, cfg) for _ in range(2)]
        for step in range(4):
            pos = rng.integers(-30, 30, size=(n, 3)).astype(float) * 0.25
            pos[1] = pos[0] + [radius[0] + radius[1], 0.0, 0.0]  # exactly at the contact reach
            events = []
            for mon, tree_from in zip(mons, (10**9, 64)):
                monkeypatch.setattr(contact, "TREE_MIN_COUNT", tree_from)
                events.append(mon.check(step, step * 10.0, pos, []))
            assert events[0] == events[1] and mons[0]._contact == mons[1]._contact and mons[0]._near == mons[1]._near
            assert ("s0", "s1") not in mons[0]._contact
            found += len(events[0])
    assert found > 100


@pytest.mark.parametrize("scenario,sets", [("sabatini-20.toml", ()),
                                           ("sabatini-20.toml", ("sensing.roe_noise_fraction=0.1",)),
                                           ("sabatini-20-camera-exact.toml", ())], ids=["rel", "rel-noisy", "scene"])
def test_a_batch_run_of_100_flies_the_same_truth_with_the_tree(tmp_path, monkeypatch: pytest.MonkeyPatch,
                                                               scenario: str, sets: tuple[str, ...]) -> None:
    """100 spacecraft of paper 002, 10 min in batch mode: the truth with the spatial index (rel stimulus,
    scenes, contact) is the truth with the (N, N) forms, bit for bit; and the per-agent message path
    (each agent's stimulus message from the same pairs) flies it too."""
    from conftest import SCENARIOS
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario
    from swarmhil.plant import contact, scene_stimulus, sensors
    from test_batch_mode import _truth_sha

    sc = load_scenario(SCENARIOS / scenario, ["dispersion.count=100", *sets]).with_overrides(duration_s=600.0)
    tree = run_in_process(sc, tmp_path / "tree", "same", record="truth")
    assert tree.summary["batch"]["used"]
    for module in (sensors, scene_stimulus, contact):
        monkeypatch.setattr(module, "TREE_MIN_COUNT", 10**9)
    run_in_process(sc, tmp_path / "matrix", "same", record="truth")
    assert _truth_sha(tmp_path / "tree" / "run.mcap") == _truth_sha(tmp_path / "matrix" / "run.mcap")
    if scenario == "sabatini-20.toml" and not sets:
        monkeypatch.undo()
        run_in_process(sc, tmp_path / "messages", "same", opts={"batch": False}, record="truth")
        assert _truth_sha(tmp_path / "tree" / "run.mcap") == _truth_sha(tmp_path / "messages" / "run.mcap")


def test_the_pairs_of_a_drawn_swarm_of_1000_are_the_matrix_ones() -> None:
    """The scaled paper 002 swarm itself (`--set dispersion.count=1000`), around its orbit: the tree's
    pairs are the matrix's at every sample (ROE -> LVLH at 12 arguments of latitude)."""
    from conftest import SCENARIOS
    from swarmhil.deploy.scenario import load_scenario
    from swarmhil.plant.dynamics.roe_linear import roe_to_lvlh

    sc = load_scenario(SCENARIOS / "sabatini-20.toml", ["dispersion.count=1000"])
    cam = CameraGeometry(**sc.camera)
    seen = 0
    for u in np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False):
        pos, _v = roe_to_lvlh(np.asarray(sc.roe_m, dtype=float), float(u), sc.orbit.mean_motion_radps)
        want, got = _brute(pos, cam, None), visible_pairs(pos, cam)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        seen += len(want[0])
    assert seen > 12 * 1000  # more than one neighbour a spacecraft on average

