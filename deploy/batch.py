"""Batch mode of an in-process run (issue 16): the plant and the flight software of every
spacecraft in one loop, without a message between them.

`run_in_process(..., record="truth")` uses it when the scenario allows (`why_not_batch`): the
plant node (plant/node.py) computes each step's truth and publishes it (and its events) to the
recorder as always, but instead of one stimulus message per spacecraft it hands the sensing
kind's stimuli as arrays (`batch`) to `BatchHook` (through the plant's interface for it,
plant/flight.py LocalFlightSoftware), which runs the spacecraft's flight software
together (agent/batch.py: the same controllers, through `step_batch`) and returns their commands.
The values are those of the message path (protobuf doubles carry float64 exactly), so the truth
is the same, bit for bit, as that of the per-agent in-process run and of the multi-process run
(tests/test_batch_mode.py). Anything a batch run would have to drop instead falls back to the
message path: a sensing kind without a batch form, a camera pipeline, beacons, companions (link
channel, viewer), or a plant that flies attitude (torques).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from agent.batch import BatchAgents
from agent.controller import ObservationBatch, OrbitInfo
from bus.keys import Keys
from plant.flight import LocalFlightSoftware, StimulusBatch
from plant.sensing.registry import SensingContext


def why_not_batch(sc: Any, opts: dict[str, Any] | None = None) -> str | None:
    """None when the scenario can run in batch mode, else the reason it cannot (one phrase)."""
    from agent.beacon import beacon_from_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from deploy.companions import enabled_companions  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from plant.sensing import has_batch_form  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if sc.fidelity not in ("linear", "j2"):
        return f"plant fidelity {sc.fidelity!r} (the mission world: attitude and bodies)"
    if not has_batch_form(sc.sensing["kind"]):
        return f"sensing kind {sc.sensing['kind']!r} has no batch form"
    if beacon_from_config(sc.sections.get("beacon"), "") is not None:
        return "beacons"
    if any(f.family == "sensor" for f in getattr(sc, "faults", ())):
        return "sensing faults (they act on the stimulus messages)"
    comps = enabled_companions(sc, opts or {})
    if comps:
        return f"companions {', '.join(c.name for c in comps)}"
    return None


class BatchHook(LocalFlightSoftware):
    """The plant's `local_agents` (plant/flight.py): arrays of stimuli in, the (N, 3) commands in force out."""

    def __init__(self, bus: Any, run: str, sc: Any) -> None:
        from deploy.agent_image import agent_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        # each spacecraft's flight software from the config its agent process would get
        cfgs = [agent_config(sc, s) for s in sc.ids]
        o = cfgs[0]["orbit"]
        orbit = OrbitInfo(o["semi_major_axis_m"], o["mean_motion_radps"])
        self.ids = list(sc.ids)
        self._ids = np.array(self.ids, dtype=object)  # ids of the pairs' neighbours by one gather
        self.agents = BatchAgents(self.ids, [(c["controller"], c["params"]) for c in cfgs], orbit,
                                  cfgs[0]["decision_period_steps"])
        keys = Keys(run)
        # the agents are up (the plant waits for their liveliness before step 0, as for processes)
        self._tokens = [bus.declare_liveliness(keys.alive(f"agent-{s}")) for s in self.ids]
        self._empty: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # observers -> (offsets, (0, 3))

    def commands(self, ctx: SensingContext, rows: np.ndarray, sense: Callable[[], StimulusBatch]) -> np.ndarray:
        """`sense()` gives the stimuli of the observers `rows` (RelBatch); not called when no
        controller of the batch looks at its observation (`observes = False`, agent/controller.py)."""
        ids = self.ids
        observers = ids if len(rows) == len(ids) else [ids[i] for i in rows.tolist()]
        if self.agents.observes:
            rel = sense()
            batch = ObservationBatch(step=ctx.step, t_s=ctx.t_s, u_rad=ctx.u_rad, observers=observers,
                                     offsets=rel.offsets, neighbour_ids=self._ids[rel.neighbour].tolist(),
                                     rel_position_m=rel.rel_position_m, rel_velocity_mps=rel.rel_velocity_mps,
                                     owner=rel.owner)
        else:
            offsets, none = self._empty.get(len(rows), (None, None))
            if offsets is None:  # no neighbours for anyone: the same read-only arrays every step
                offsets, none = self._empty[len(rows)] = (np.zeros(len(rows) + 1, dtype=np.int64), np.zeros((0, 3)))
                offsets.setflags(write=False)
                none.setflags(write=False)
            batch = ObservationBatch(step=ctx.step, t_s=ctx.t_s, u_rad=ctx.u_rad, observers=observers,
                                     offsets=offsets, neighbour_ids=[], rel_position_m=none, rel_velocity_mps=none)
        return self.agents.step(rows, batch)

    @property
    def faults(self) -> dict[str, dict[str, int]]:
        return self.agents.faults


class TruthLog:
    """The plant's truth of every step as arrays, kept while the run goes (PlantNode `on_truth`):
    what `dashboards.truth_io.read_truth` reads back from the recording, without reading it
    (issue 16: a campaign computes each run's metrics from these). The values are the ones the
    truth messages carry (protobuf doubles are float64), so `arrays()` equals `read_truth` of the
    run's recording exactly (tests/test_campaign.py)."""

    def __init__(self, ids: list[str], steps: int, a_m: float, n_radps: float) -> None:
        n, t = len(ids), steps + 1
        self.ids, self.a_m, self.n_radps = list(ids), float(a_m), float(n_radps)
        self.k = 0
        self.step = np.empty(t, dtype=np.int64)
        self.t_s, self.u_rad = np.empty(t), np.empty(t)
        self.pos, self.vel, self.acc = np.empty((t, n, 3)), np.empty((t, n, 3)), np.empty((t, n, 3))
        self.dv, self.alive, self.roe = np.empty((t, n)), np.empty((t, n), dtype=bool), np.empty((t, n, 6))

    def __call__(self, step: int, t_s: float, u_rad: float, pos: np.ndarray, vel: np.ndarray, dv: np.ndarray,
                 alive: np.ndarray, acc: np.ndarray, roe: np.ndarray) -> None:
        k = self.k
        if k == len(self.t_s) or (k and step <= self.step[k - 1]):
            return  # beyond the planned steps, or a repeated step (read_truth keeps the first)
        self.step[k], self.t_s[k], self.u_rad[k] = step, t_s, u_rad
        self.pos[k], self.vel[k], self.dv[k], self.alive[k], self.acc[k], self.roe[k] = pos, vel, dv, alive, acc, roe
        self.k = k + 1

    def arrays(self, run: str) -> Any:
        """The TruthArrays of the steps so far (dashboards/truth_io.py)."""
        from dashboards.truth_io import TruthArrays, align_accel  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        k = self.k
        acc, recorded_as = align_accel(self.acc[:k].copy(), self.dv[:k], self.t_s[:k])
        return TruthArrays(run=run, ids=list(self.ids), step=self.step[:k].copy(), t_s=self.t_s[:k].copy(),
                           u_rad=self.u_rad[:k].copy(), semi_major_axis_m=self.a_m, mean_motion_radps=self.n_radps,
                           position_m=self.pos[:k].copy(), velocity_mps=self.vel[:k].copy(),
                           delta_v_mps=self.dv[:k].copy(), alive=self.alive[:k].copy(), accel_mps2=acc,
                           roe_m=self.roe[:k].copy(), accel_recorded_as=recorded_as)
