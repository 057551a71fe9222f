"""The flight software of many spacecraft in one object: the batch mode's agents (issue 16).

What N `AgentNode`s (agent/node.py) do with a relative-state stimulus, for all of them at once:
each spacecraft has its own controller (made by the same registry, with its own parameters); at
a decision step they are stepped together through `agent.controller.step_batch` (one vectorised
pass where the controller class has one, each `step` in turn otherwise), and the command of each
is checked as the agent node checks it (a controller that raises, or returns a non-finite or
malformed acceleration, commands zero for that spacecraft and the fault is counted or logged).
Between decision steps the previous command stays in force. No message is built: the observation
arrives as arrays and the commands leave as an (N, 3) array (deploy/batch.py wires it to the plant).

With the camera (`scene` stimulus, issue 36), `BatchPerception` runs each spacecraft's own
`Perception` (agent/perception.py: camera -> blobs -> navigator) on the values its stimulus message
would carry, with the command in force as its own acceleration, as `AgentNode.handle` does, and
hands the controllers the tracks as one ObservationBatch.
"""
from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Command, CommandBatch, Observation, ObservationBatch, OrbitInfo, step_batch

log = logging.getLogger("swarmhil.agent")


class BatchAgents:
    def __init__(self, ids: list[str], controllers: list[tuple[str, dict[str, Any]]], orbit: OrbitInfo,
                 decision_period_steps: int = 1) -> None:
        self.ids = list(ids)
        self.controllers = [make_controller(name, sid, orbit, params) for sid, (name, params) in zip(self.ids, controllers)]
        self.decision_period_steps = max(1, int(decision_period_steps))
        self.accel_mps2 = np.zeros((len(self.ids), 3))  # the command in force, per spacecraft
        self.torque_nm = np.zeros((len(self.ids), 3))   # its body-frame torque (0 for a controller without one)
        self._torques = False  # may a row of torque_nm be other than 0 (else a decision without torques keeps it)
        self.modes = ["idle"] * len(self.ids)
        self.faults: dict[str, dict[str, int]] = {}
        self.steps = 0
        self.last: CommandBatch | None = None  # the last decision's commands (full Commands on demand)
        self.replaced: list[int] = []  # rows of the last decision whose command became zero (raised, non-finite)
        # does any controller read its observation (a class may declare `observes = False`)?
        self.observes = any(getattr(c, "observes", True) for c in self.controllers)
        kinds = {type(c) for c in self.controllers}
        # the class's own batch path for all of them (what `step_batch` picks), looked up once
        self._all = getattr(next(iter(kinds)), "step_batch", None) if len(kinds) == 1 else None

    def _fault(self, i: int, step: int, logged: bool = False) -> None:
        f = self.faults.setdefault(self.ids[i], {})
        n = f["controller"] = f.get("controller", 0) + 1
        if logged:  # (a batch path caught and logged it: `CommandBatch.raised`)
            log.warning("%s: controller fault #%d at step %d", self.ids[i], n, step)
        elif n == 1:
            log.exception("%s: controller fault at step %d (handled; further ones are only counted)", self.ids[i], step)
        else:
            log.warning("%s: controller fault #%d at step %d", self.ids[i], n, step)

    def _decide(self, rows: np.ndarray, batch: ObservationBatch) -> CommandBatch:
        if len(rows) == len(self.controllers):  # everyone alive (rows are sorted and unique)
            ctrls = self.controllers
        else:
            ctrls = [self.controllers[i] for i in rows.tolist()]
        try:
            if self._all is not None and ctrls is self.controllers:
                return self._all(ctrls, batch)
            return step_batch(ctrls, batch)
        except Exception:  # noqa: BLE001 - find the spacecraft whose software raised: each on its own
            cmds = []
            for r, (i, c) in enumerate(zip(rows.tolist(), ctrls)):
                try:
                    cmds.append(c.step(batch.observation(r)))
                except Exception:  # noqa: BLE001 - as AgentNode: command zero this step, count, go on
                    self._fault(i, batch.step)
                    cmds.append(Command(accel_mps2=np.zeros(3), mode="fault"))
            return CommandBatch.of(cmds)

    def step(self, rows: np.ndarray, batch: ObservationBatch) -> np.ndarray:
        """The observers `rows` (indices into ids) see `batch`; returns the (N, 3) commands in force
        (their torques: `torque_nm`)."""
        if batch.step % self.decision_period_steps == 0 and len(rows):
            cb = self._decide(rows, batch)
            for r in cb.raised:  # counted as AgentNode counts a step that raised
                self._fault(int(rows[r]), batch.step, logged=True)
            acc = np.asarray(cb.accel_mps2, dtype=float)
            tq = None if cb.torque_nm is None else np.asarray(cb.torque_nm, dtype=float)  # None: zeros
            modes = list(cb.modes)
            self.replaced = list(cb.raised)
            # a finite sum means every entry is finite; otherwise find the rows (or the sum overflowed).
            # As AgentNode: a non-finite acceleration or torque commands zero (no torque) instead
            total = 0.0 if cb.finite else np.add.reduce(acc, axis=None) + (0.0 if tq is None else np.add.reduce(tq, axis=None))
            bad = None
            if not math.isfinite(total):
                tq = np.zeros_like(acc) if tq is None else tq
                bad = ~(np.isfinite(acc).all(axis=1) & np.isfinite(tq).all(axis=1))
            if bad is not None and bad.any() and tq is not None:
                acc, tq = acc.copy(), tq.copy()
                for r in np.flatnonzero(bad).tolist():
                    i = int(rows[r])
                    log.error("%s: controller %s returned accel %r, torque %r; commanding zero", self.ids[i],
                              self.controllers[i].name, acc[r], tq[r])
                    acc[r] = tq[r] = 0.0
                    modes[r] = "fault"
                    self.replaced.append(r)
            if len(rows) == len(self.ids):
                self.accel_mps2[:] = acc
                if tq is not None or self._torques:
                    self.torque_nm[:] = 0.0 if tq is None else tq
                    self._torques = tq is not None
                self.modes = modes
            else:
                self.accel_mps2[rows] = acc
                self.torque_nm[rows] = 0.0 if tq is None else tq
                self._torques = True
                for r, i in enumerate(rows.tolist()):
                    self.modes[i] = modes[r]
            self.last = cb
        self.steps += 1
        return self.accel_mps2


def count_fault(faults: dict[str, dict[str, int]], sid: str, where: str, step: int) -> None:
    """Count a handled fault of spacecraft `sid` ("nav" / "controller"); the first of each kind is
    logged with its traceback (agent/node.py AgentNode._fault, the same messages)."""
    f = faults.setdefault(sid, {})
    n = f[where] = f.get(where, 0) + 1
    if n == 1:
        log.exception("%s: %s fault at step %d (handled; further ones are only counted)", sid, where, step)
    else:
        log.warning("%s: %s fault #%d at step %d", sid, where, n, step)


class BatchPerception:
    """Each spacecraft's camera pipeline (agent/perception.py `Perception`, one per spacecraft, built
    from its agent config) fed with the values of its `scene` stimulus: per observer row r, bodies
    offsets[r]:offsets[r+1] with camera-frame positions (P, 3) and attitude quaternions w, x, y, z
    (P, 4), which become matrices as `Perception.observe` makes them (quat_to_matrix is elementwise:
    all rows at once give each row's own matrix), through agent/perception.py `observe_many` (every
    observer's imaging, then the navigators of all observers together (EKF, rough), bit for bit each one's
    own update, then each one's observation). As AgentNode.handle: the own acceleration is the
    command in force before this step's decision; a navigation exception is logged (the first),
    counted in `faults[id]["nav"]`, the spacecraft observes nothing this step and its navigation
    restarts from the next frame."""

    def __init__(self, ids: list[str], perceptions: list[Any], faults: dict[str, dict[str, int]]) -> None:
        self.ids = list(ids)
        self.perceptions = perceptions
        self.faults = faults
        # the paper's exact imaging with one camera and shape for all: every spacecraft's blobs at once
        r0 = perceptions[0].vision.renderer if perceptions else None
        self._exact = r0 is not None and all(p.vision.imaging == "exact" and p.vision.renderer.camera == r0.camera
                                             and repr(p.vision.renderer.shape) == repr(r0.shape) for p in perceptions)  # (its parameters)

    def observe(self, step: int, t_s: float, u_rad: float, rows: np.ndarray, observers: list[str], offsets: np.ndarray,
                position_cam_m: np.ndarray, attitude_wxyz: np.ndarray, own_accel_mps2: np.ndarray) -> ObservationBatch:
        from swarmhil.agent.perception import observe_many  # scene sensing only (the camera stack)

        idx = rows.tolist()
        accel = own_accel_mps2.tolist()
        pers = [self.perceptions[i] for i in idx]
        # (fresh arrays, as the agent's from its message, and its command's acceleration)
        got = observe_many(pers, step, t_s, u_rad, offsets, position_cam_m, attitude_wxyz,
                           [np.array(accel[i], dtype=float) for i in idx], self._exact)
        out = []
        for i, per, obs in zip(idx, pers, got):
            if isinstance(obs, Exception):  # a navigation fault must not stop the flight software (AgentNode)
                try:
                    raise obs
                except Exception:  # noqa: BLE001 - logged with its traceback (the first), counted
                    count_fault(self.faults, self.ids[i], "nav", step)
                per.reset()
                obs = Observation(step=step, t_s=t_s, u_rad=u_rad, neighbour_ids=[],
                                  rel_position_m=np.zeros((0, 3)), rel_velocity_mps=np.zeros((0, 3)))
            out.append(obs)
        return ObservationBatch.of(observers, out)
