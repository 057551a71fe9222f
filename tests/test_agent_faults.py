"""A fault inside the flight software (navigation or controller raising) is handled: counted, logged,
the command is still published every step and navigation restarts (issue 4: an EKF LinAlgError used
to stop an agent's step, and the plant held its previous command)."""
from __future__ import annotations

import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import header
from swarmhil.bus.keys import Keys
from swarmhil.bus.memory import MemoryBus
from conftest import SCENARIOS
from swarmhil.deploy.launcher import make_agent
from swarmhil.deploy.scenario import load_scenario


def _stimulus(run: str, sid: str, step: int) -> pb.SceneStimulus:
    return pb.SceneStimulus(header=header(run, "plant", step, 10.0 * step, step), u_rad=0.001 * step)


def test_nav_and_controller_faults_are_counted_and_commands_keep_coming():
    sc = load_scenario(SCENARIOS / "sabatini-20-camera-filter.toml")
    bus, run, sid = MemoryBus(), "faults", sc.ids[0]
    acts: list[pb.ActuatorCommand] = []
    bus.subscribe(Keys(run).act(sid), lambda k, p: acts.append(pb.ActuatorCommand.FromString(p)))
    node = make_agent(bus, run, sc, sid)
    good_vision = node.perception.vision

    def broken(*_a, **_k):
        raise np.linalg.LinAlgError("Singular matrix")

    node.perception.vision.step = broken
    node.handle(_stimulus(run, sid, 0))
    assert node.faults == {"nav": 1}
    assert node.perception.vision is not good_vision  # navigation restarted afresh
    node.handle(_stimulus(run, sid, 1))  # the fresh pipeline works
    assert node.faults == {"nav": 1}

    def broken_controller(_obs):
        raise RuntimeError("DRE table lookup failed")

    node.controller.step = broken_controller
    node.handle(_stimulus(run, sid, 2))
    assert node.faults == {"nav": 1, "controller": 1}
    assert [int(a.header.step) for a in acts] == [0, 1, 2]  # a command every step, faults or not
    assert np.allclose([acts[2].accel_mps2.x, acts[2].accel_mps2.y, acts[2].accel_mps2.z], 0.0)
