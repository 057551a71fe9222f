"""Issue 36: the camera scenarios (`scene` stimulus, a [nav] table) run in batch mode
(deploy/batch.py: the plant's SceneBatch arrays, each spacecraft's own Perception in
agent/batch.py BatchPerception), and their truth is the per-agent message path's, bit for bit.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import SCENARIOS
from test_batch_mode import _truth_sha  # the truth messages' sha256 and count, as the other batch twins
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario


@pytest.mark.parametrize("name", ["sabatini-20-camera-exact", "sabatini-20-camera-filter"], ids=["exact-rough", "render-ekf"])
def test_camera_batch_truth_equals_the_per_agent_path(tmp_path: Path, name: str) -> None:
    from swarmhil.deploy.batch import why_not_batch

    sc = load_scenario(SCENARIOS / f"{name}.toml").with_overrides(duration_s=1200.0)
    assert why_not_batch(sc) is None and len(sc.ids) == 20
    full = run_in_process(sc, tmp_path / "all", "cam")
    batch = run_in_process(sc, tmp_path / "truth", "cam", record="truth")
    assert not full.summary["batch"]["used"] and batch.summary["batch"] == {"used": True, "why_not": None}
    sha_all, n = _truth_sha(tmp_path / "all" / "run.mcap")
    assert (sha_all, n) == _truth_sha(tmp_path / "truth" / "run.mcap") and n == 121
    assert batch.summary["delta_v_total_mps"] == full.summary["delta_v_total_mps"] > 0.0
    assert batch.summary["agent_faults"] == full.summary["agent_faults"] == {}


@pytest.mark.parametrize("name", ["sabatini-20-camera-exact", "sabatini-20-camera-filter"], ids=["exact-rough", "render-ekf"])
def test_a_navigation_fault_in_batch_mode_is_handled_as_by_the_agent(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    """A navigation exception: counted per spacecraft ("nav"), no neighbours that step, navigation
    restarted; the same counts and the same truth as the agents' (AgentNode.handle)."""
    from swarmhil.agent.perception import Perception

    real = Perception._observation  # what both paths call after the navigator's update (batch: observe_blobs)

    def flaky(self, step, t_s, u_rad):
        if step % 7 == 3 and len(self.tracks) % 2 == 1:  # deterministic in the data: the same frames in both paths
            raise np.linalg.LinAlgError("injected")
        return real(self, step, t_s, u_rad)

    monkeypatch.setattr(Perception, "_observation", flaky)
    sc = load_scenario(SCENARIOS / f"{name}.toml").with_overrides(duration_s=300.0)
    full = run_in_process(sc, tmp_path / "all", "nf")
    batch = run_in_process(sc, tmp_path / "truth", "nf", record="truth")
    assert batch.summary["batch"]["used"]
    faults = full.summary["agent_faults"]
    assert faults and all(set(f) == {"nav"} for f in faults.values())
    assert batch.summary["agent_faults"] == faults
    assert _truth_sha(tmp_path / "all" / "run.mcap") == _truth_sha(tmp_path / "truth" / "run.mcap")


@pytest.mark.parametrize("sets", [("sensing.pointing_error_rad=[0.002, -0.001, 0.003]",),
                                  ("sensing.pointing_error_rad=[0.002, -0.001, 0.003]", "sensing.pointing_jitter_rad=0.001")],
                         ids=["pointing-bias", "pointing-jitter"])
def test_camera_batch_with_pointing_errors(tmp_path: Path, sets: tuple[str, ...]) -> None:
    """The plant's scenes of all observers at once (a fixed pointing error: one rotation for all) and
    observer by observer (jitter: each its own draw, in the message path's order) are the messages' values."""
    sc = load_scenario(SCENARIOS / "sabatini-20-camera-exact.toml", list(sets)).with_overrides(duration_s=300.0)
    full = run_in_process(sc, tmp_path / "all", "pe")
    batch = run_in_process(sc, tmp_path / "truth", "pe", record="truth")
    assert batch.summary["batch"]["used"]
    assert _truth_sha(tmp_path / "all" / "run.mcap") == _truth_sha(tmp_path / "truth" / "run.mcap")
    assert batch.summary["delta_v_total_mps"] == full.summary["delta_v_total_mps"] > 0.0
