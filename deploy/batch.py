"""Batch mode of an in-process run (issue 16): the plant and the flight software of every
spacecraft in one loop, without a message between them.

`run_in_process(..., record="truth")` uses it when the scenario allows (`why_not_batch`): the
plant node (plant/node.py) computes each step's truth and publishes it (and its events) to the
recorder as always, but instead of one stimulus message per spacecraft it hands the sensing
kind's stimuli as arrays (`batch`) to `BatchHook`, which runs the spacecraft's flight software
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


def why_not_batch(sc: Any, opts: dict[str, Any] | None = None) -> str | None:
    """None when the scenario can run in batch mode, else the reason it cannot (one phrase)."""
    from agent.beacon import beacon_from_config
    from deploy.companions import enabled_companions
    from plant.sensing import has_batch_form

    if sc.fidelity not in ("linear", "j2"):
        return f"plant fidelity {sc.fidelity!r} (the mission world: attitude and bodies)"
    if not has_batch_form(sc.sensing["kind"]):
        return f"sensing kind {sc.sensing['kind']!r} has no batch form"
    if beacon_from_config(sc.sections.get("beacon"), "") is not None:
        return "beacons"
    comps = enabled_companions(sc, opts or {})
    if comps:
        return f"companions {', '.join(c.name for c in comps)}"
    return None


class BatchHook:
    """The plant's `local_agents`: arrays of stimuli in, the (N, 3) commands in force out."""

    def __init__(self, bus: Any, run: str, sc: Any) -> None:
        from deploy.agent_image import agent_config

        # each spacecraft's flight software from the config its agent process would get
        cfgs = [agent_config(sc, s) for s in sc.ids]
        o = cfgs[0]["orbit"]
        orbit = OrbitInfo(o["semi_major_axis_m"], o["mean_motion_radps"])
        self.ids = list(sc.ids)
        self.agents = BatchAgents(self.ids, [(c["controller"], c["params"]) for c in cfgs], orbit,
                                  cfgs[0]["decision_period_steps"])
        keys = Keys(run)
        # the agents are up (the plant waits for their liveliness before step 0, as for processes)
        self._tokens = [bus.declare_liveliness(keys.alive(f"agent-{s}")) for s in self.ids]

    def __call__(self, ctx: Any, rows: np.ndarray, sense: Callable[[], Any]) -> np.ndarray:
        """`sense()` gives the stimuli of the observers `rows` (RelBatch); not called when no
        controller of the batch looks at its observation (`observes = False`, agent/controller.py)."""
        ids = self.ids
        observers = ids if len(rows) == len(ids) else [ids[i] for i in rows.tolist()]
        if self.agents.observes:
            rel = sense()
            batch = ObservationBatch(step=ctx.step, t_s=ctx.t_s, u_rad=ctx.u_rad, observers=observers,
                                     offsets=rel.offsets, neighbour_ids=[ids[k] for k in rel.neighbour.tolist()],
                                     rel_position_m=rel.rel_position_m, rel_velocity_mps=rel.rel_velocity_mps)
        else:
            batch = ObservationBatch(step=ctx.step, t_s=ctx.t_s, u_rad=ctx.u_rad, observers=observers,
                                     offsets=np.zeros(len(rows) + 1, dtype=np.int64), neighbour_ids=[],
                                     rel_position_m=np.zeros((0, 3)), rel_velocity_mps=np.zeros((0, 3)))
        return self.agents.step(rows, batch)

    @property
    def faults(self) -> dict[str, dict[str, int]]:
        return self.agents.faults
