"""Issue 16, the batch mode's per-step costs: what was removed changes neither the truth nor the
recording. The recorder takes a truth's log time from the plant's stamp on the in-process bus
instead of decoding it (every log time equal to the decoding path's and to epoch + header.t); a
controller that does not observe (`null`, drift-20) gets no stimuli computed, and its truth is
still the message path's; the in-memory bus delivers stamps and says who wants a key."""
from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.recorder import epoch_ns
from conftest import SCENARIOS
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario


def _truths(path: Path) -> list[tuple[int, bytes]]:
    with open(path, "rb") as f:
        return [(m.log_time, m.data) for _s, ch, m in make_reader(f).iter_messages(log_time_order=False)
                if ch.topic == "truth"]


@pytest.mark.parametrize("name", ["drift-20", "sabatini-20"])
def test_batch_truth_and_log_times_equal_the_message_path(tmp_path: Path, name: str) -> None:
    sc = load_scenario(SCENARIOS / f"{name}.toml").with_overrides(duration_s=600.0)
    full = run_in_process(sc, tmp_path / "all", "same")
    batch = run_in_process(sc, tmp_path / "truth", "same", record="truth")
    assert batch.summary["batch"]["used"]
    a, b = _truths(tmp_path / "all" / "run.mcap"), _truths(tmp_path / "truth" / "run.mcap")
    assert len(a) == 61 and a == b  # same payloads, same log times
    epoch = epoch_ns(sc.resolved()["run"].get("epoch_utc"))
    for log_time, data in b:
        assert log_time == epoch + round(pb.Truth.FromString(data).header.t * 1e9)
    assert batch.summary["delta_v_total_mps"] == full.summary["delta_v_total_mps"]


def test_memory_bus_stamps_and_wants() -> None:
    from swarmhil.bus.memory import MemoryBus

    bus = MemoryBus()
    got: list = []
    assert not bus.wants("swarm/r/clock")
    bus.subscribe("swarm/r/*", lambda k, p: got.append(("plain", k, p)))
    bus.subscribe("swarm/r/truth", lambda k, p, t: got.append(("stamped", k, p, t)), stamped=True)
    assert bus.wants("swarm/r/clock") and not bus.wants("swarm/q/clock")
    bus.publish("swarm/r/truth", b"x", 5)
    bus.publish("swarm/r/truth", b"y")
    assert got == [("plain", "swarm/r/truth", b"x"), ("stamped", "swarm/r/truth", b"x", 5),
                   ("plain", "swarm/r/truth", b"y"), ("stamped", "swarm/r/truth", b"y", None)]


@pytest.mark.parametrize("sets", [(), ("sensing.roe_noise_fraction=0.1",)], ids=["ideal", "noisy"])
def test_kept_truth_equals_the_recording_read_back(tmp_path: Path, sets: tuple[str, ...]) -> None:
    """run_in_process(keep_truth=True) (a campaign's metrics without read-back): every array equal to
    read_truth of the run's own recording, and so its metrics too."""
    import numpy as np

    from swarmhil.dashboards.metrics import compute_metrics
    from swarmhil.dashboards.truth_io import read_truth

    sc = load_scenario(SCENARIOS / "sabatini-20.toml", list(sets)).with_overrides(duration_s=1800.0, seed=5)
    res = run_in_process(sc, tmp_path, "kept", record="truth", keep_truth=True)
    kept, back = res.truth, read_truth(tmp_path / "run.mcap")
    assert kept is not None and kept.n_steps == 181 and kept.ids == back.ids and kept.run == back.run
    for f in ("step", "t_s", "u_rad", "position_m", "velocity_mps", "delta_v_mps", "alive", "accel_mps2", "roe_m"):
        a, b = getattr(kept, f), getattr(back, f)
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), f
    assert (kept.semi_major_axis_m, kept.mean_motion_radps, kept.accel_recorded_as) == \
        (back.semi_major_axis_m, back.mean_motion_radps, back.accel_recorded_as)
    assert np.abs(kept.accel_mps2).max() > 0
    assert compute_metrics(kept).summary == compute_metrics(back).summary
