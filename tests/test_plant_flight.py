"""The plant runs in-process flight software through its own interface (plant/flight.py
LocalFlightSoftware): any implementation, not only deploy/batch.py's BatchHook. That BatchHook's
truth equals the message path's, bit for bit, is tests/test_batch_mode.py's job."""
from __future__ import annotations

from typing import Callable

import numpy as np

from swarmhil.bus.keys import Keys
from swarmhil.bus.memory import MemoryBus
from conftest import SCENARIOS
from swarmhil.deploy.batch import BatchHook
from swarmhil.deploy.scenario import load_scenario, plant_config
from swarmhil.plant.flight import LocalFlightSoftware, StimulusBatch
from swarmhil.plant.node import PlantNode
from swarmhil.plant.sensing import SensingContext

ACCEL_MPS2 = 1e-5


class ConstantThrust(LocalFlightSoftware):
    """Flight software that thrusts +x at ACCEL_MPS2 and keeps what it was called with."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.calls: list[tuple[int, list[int], int]] = []

    def commands(self, ctx: SensingContext, rows: np.ndarray, sense: Callable[[], StimulusBatch]) -> np.ndarray:
        stim = sense()
        assert len(stim.offsets) == len(rows) + 1 and len(stim.neighbour) == stim.offsets[-1]
        self.calls.append((ctx.step, rows.tolist(), int(stim.offsets[-1])))
        return np.tile([ACCEL_MPS2, 0.0, 0.0], (self.n, 1))


def test_the_plant_flies_any_local_flight_software() -> None:
    cfg = plant_config(load_scenario(SCENARIOS / "sabatini-20.toml").with_overrides(duration_s=100.0))
    bus, run = MemoryBus(), "local-fsw"
    fsw = ConstantThrust(len(cfg.ids))
    _tokens = [bus.declare_liveliness(Keys(run).alive(f"agent-{s}")) for s in cfg.ids]
    plant = PlantNode(bus, run, cfg, expect_processes=(), local_agents=fsw)
    plant.wait_ready(timeout_s=1.0)
    summary = plant.run()
    assert [c[0] for c in fsw.calls] == list(range(cfg.steps)) and cfg.steps == 10
    assert all(rows == list(range(len(cfg.ids))) for _, rows, _ in fsw.calls)
    assert sum(p for _, _, p in fsw.calls) > 0  # the camera saw neighbours
    # every spacecraft thrusted ACCEL_MPS2 over the whole run, nothing else
    assert np.allclose(list(summary["delta_v_mps"].values()), ACCEL_MPS2 * 100.0, rtol=1e-12, atol=0)
    assert LocalFlightSoftware in BatchHook.__mro__  # deploy implements the interface the plant owns
