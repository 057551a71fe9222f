"""Issue 16: the batch mode of in-process runs (deploy/batch.py, `run_in_process(record="truth")`)
gives the truth of the per-agent message path bit for bit, falls back where it would drop
something, and handles a faulty controller as an agent node does.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from conftest import SCENARIOS, read_mcap
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario


def _truth_sha(path: Path) -> tuple[str, int]:
    from mcap.reader import make_reader

    h, n = hashlib.sha256(), 0
    with open(path, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages(log_time_order=False):
            if ch.topic == "truth":
                h.update(m.data)
                n += 1
    return h.hexdigest(), n


@pytest.mark.parametrize("sets", [(), ("sensing.roe_noise_fraction=0.1",)], ids=["ideal", "noisy"])
def test_batch_truth_equals_the_message_path(tmp_path: Path, sets: tuple[str, ...]) -> None:
    sc = load_scenario(SCENARIOS / "sabatini-20.toml", list(sets)).with_overrides(duration_s=600.0)
    full = run_in_process(sc, tmp_path / "all", "same", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "truth", "same", record="truth")
    assert not full.summary["batch"]["used"] and batch.summary["batch"] == {"used": True, "why_not": None}
    sha_all, n_all = _truth_sha(tmp_path / "all" / "run.mcap")
    assert (sha_all, n_all) == _truth_sha(tmp_path / "truth" / "run.mcap") and n_all == 61
    assert batch.summary["delta_v_total_mps"] == full.summary["delta_v_total_mps"] > 0.0
    topics = {t for t, *_ in read_mcap(tmp_path / "truth" / "run.mcap")}
    assert topics == {"truth", "event"}  # the light recording: no stimuli, commands, telemetry, scene
    assert batch.summary["recording"]["messages"] < full.summary["recording"]["messages"] / 20


def test_batch_mode_falls_back_where_it_would_drop_something(tmp_path: Path) -> None:
    from swarmhil.deploy.batch import why_not_batch

    beacon = load_scenario(SCENARIOS / "sabatini-20-beacon.toml").with_overrides(duration_s=100.0)
    assert why_not_batch(beacon) == "beacons"
    assert why_not_batch(load_scenario(SCENARIOS / "sabatini-20-camera-filter.toml")) is None  # (issue 36: test_batch_camera.py)
    res = run_in_process(beacon, tmp_path / "b", "fb", record="truth")
    assert res.summary["batch"] == {"used": False, "why_not": "beacons"} and res.summary["steps"] == 10
    assert {t for t, *_ in read_mcap(tmp_path / "b" / "run.mcap")} == {"truth", "event"}


def test_a_faulty_controller_in_batch_mode_is_counted_and_commands_zero(tmp_path: Path) -> None:
    """One controller raises on odd steps, one commands NaN, one -inf: their agents command zero
    (mode "fault"), in batch mode as an agent node does; with every packet recorded, the batch
    run's packets are the per-agent run's (tests/test_batch_packets.py)."""
    from test_batch_packets import assert_same_packets

    from swarmhil.agent.controller import Command, register

    class Faulty:
        name = "test-faulty-batch"

        def __init__(self, sid: str) -> None:
            self.sid = sid

        def step(self, obs):
            if self.sid == "sc03" and obs.step % 2 == 1:
                raise RuntimeError("broken on odd steps")
            if self.sid == "sc04":
                return Command(accel_mps2=np.array([np.nan, 0.0, 0.0]))
            if self.sid == "sc06":
                return Command(accel_mps2=np.array([0.0, -np.inf, 0.0]), mode="inf")
            return Command(accel_mps2=np.array([0.0, 1e-5, -0.0]), mode="push")

    register("test-faulty-batch")(lambda sid, orbit, params: Faulty(sid))
    sc = load_scenario(SCENARIOS / "sabatini-20.toml", ['controller.name="test-faulty-batch"',
                                                        "controller.params={}"]).with_overrides(duration_s=60.0)
    full = run_in_process(sc, tmp_path / "all", "f", opts={"batch": False})
    batch = run_in_process(sc, tmp_path / "truth", "f", record="truth")
    packets = run_in_process(sc, tmp_path / "packets", "f")
    assert batch.summary["batch"]["used"] and packets.summary["batch"]["used"] and not full.summary["batch"]["used"]
    assert (batch.summary["agent_faults"] == full.summary["agent_faults"] == packets.summary["agent_faults"]
            == {"sc03": {"controller": 3}})
    assert _truth_sha(tmp_path / "all" / "run.mcap") == _truth_sha(tmp_path / "truth" / "run.mcap")
    dv = batch.summary["delta_v_mps"]
    assert dv["sc04"] == dv["sc06"] == 0.0 and dv["sc05"] == pytest.approx(6e-4) and dv["sc03"] == pytest.approx(3e-4)
    assert_same_packets(tmp_path / "all" / "run.mcap", tmp_path / "packets" / "run.mcap")
    modes = {m.mode for t, _l, _p, m in read_mcap(tmp_path / "packets" / "run.mcap") if t in ("sc/sc03/tm", "sc/sc04/tm", "sc/sc06/tm")}
    assert modes == {"fault", "push"}
