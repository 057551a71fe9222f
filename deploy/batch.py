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
(tests/test_batch_mode.py). The mission worlds (cw, inertial: papers 001, 003, 004, issue 29) run
in batch mode too: a sensing kind without a batch form hands its messages themselves (built as for
the bus, read by the agent's own `observation_from_rel`), and the inter-satellite link is the
channel's own model (`BatchLink`: link/model.py `LinkModel`, fed as link/node.py feeds it, so the
same packets reach the same receivers at the same steps; tests/test_batch_missions.py). Anything a
batch run would have to drop instead falls back to the message path: beacons,
sensing faults or the viewer companion. Spacecraft that fly attitude (paper 000) run in it too: the
commands carry their torques (the plant's (N, 6) form, plant/flight.py). The camera (`scene`, issue
36) too: the plant hands each observer's scene as arrays (plant/scene_stimulus.py SceneBatch: the
values of its message) and every spacecraft's own perception turns them into its tracks
(agent/batch.py BatchPerception), as its agent node would.
"""
from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from swarmhil.agent.batch import BatchAgents
from swarmhil.agent.controller import CommandBatch, ObservationBatch, OrbitInfo
from swarmhil.agent.node import observation_from_rel
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import header
from swarmhil.bus.keys import Keys
from swarmhil.deploy.batch_packets import BatchPackets, LinkPackets, why_not_packets
from swarmhil.deploy.scenario import plant_config
from swarmhil.link.faults import LinkFaults
from swarmhil.link.model import COUNTER_FIELDS, LinkModel, check_tx, parse_link_config
from swarmhil.link.node import enabled as channel_enabled
from swarmhil.plant.flight import LocalFlightSoftware, StimulusBatch, StimulusMessages
from swarmhil.plant.sensing.registry import SensingContext, sensing_message


def why_not_batch(sc: Any, opts: dict[str, Any] | None = None, record: str = "truth") -> str | None:
    """None when the scenario can run in batch mode recording `record` ("truth", or "all": every
    packet, deploy/batch_packets.py), else the reason it cannot (one phrase)."""
    from swarmhil.agent.beacon import beacon_from_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.companions import enabled_companions  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.sensing import has_batch_form  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if (opts or {}).get("batch") is False:
        return "batch mode off (opts batch = false)"
    if sc.fidelity not in ("linear", "j2", "cw", "inertial"):
        return f"plant fidelity {sc.fidelity!r}"
    kind = sc.sensing["kind"]
    if not has_batch_form(kind) and sensing_message(kind) is not pb.Measurements:
        return f"sensing kind {kind!r} has no batch form"
    if beacon_from_config(sc.sections.get("beacon"), "") is not None:
        return "beacons"
    if any(f.family == "sensor" for f in getattr(sc, "faults", ())):
        return "sensing faults (they act on the stimulus messages)"
    comps = [c for c in enabled_companions(sc, opts or {}) if c.name != "channel"]  # (the link: BatchLink)
    if comps:
        return f"companions {', '.join(c.name for c in comps)}"
    if record == "all":
        return why_not_packets(sc)
    return None


class RxPacket:
    """One delivery of a batch run as its receiver reads it: the fields of the `IslPacket` the channel
    would publish on the receiver's isl/rx key (link/node.py `_publish`), `src`, `dst`, `type`,
    `payload`, `sent_t`, and its `header` (source "channel", the receive step and time, the key's
    seq), which is built only when read. `message()` is the IslPacket itself. The flight software
    reads the same values as from the message (protobuf doubles carry float64 exactly), without a
    protobuf message made per delivery (issue 29: ~3.5 us each, 42 a step in surround-6)."""

    __slots__ = ("_link", "_rx_step", "_seq", "src", "dst", "type", "payload", "sent_t")

    def __init__(self, link: "BatchLink", rx_step: int, seq: int, src: str, dst: str, typ: str, payload: bytes,
                 sent_t: float) -> None:
        self._link, self._rx_step, self._seq = link, rx_step, seq
        self.src, self.dst, self.type, self.payload, self.sent_t = src, dst, typ, payload, sent_t

    @property
    def header(self) -> pb.Header:
        return header(self._link.run, "channel", self._rx_step, self._rx_step * self._link.step_s, self._seq)

    def message(self) -> pb.IslPacket:
        """The IslPacket the channel publishes for this delivery."""
        return pb.IslPacket(header=self.header, src=self.src, dst=self.dst, type=self.type, payload=self.payload,
                            sent_t=self.sent_t)


class BatchLink:
    """The inter-satellite link of a batch run: the channel companion's model (link/model.py
    `LinkModel`) fed as link/node.py `ChannelNode` feeds it in a lockstep run. At step k: the truth
    of step k (the positions the truth message carries, in the order of the ids), then every
    packet the agents transmit at step k (dated k, with its sender's sequence number, checked by
    `check_tx` like a packet on the bus), then the window of step k, whose deliveries (an
    `RxPacket` each: the `IslPacket` the channel publishes, as its receiver reads it) wait in the receivers' inboxes until their next
    decision step (agent/node.py: `obs.isl_rx`)."""

    def __init__(self, run: str, sc: Any) -> None:
        self.run = run
        self.cfg = parse_link_config(sc.sections["link"], sc.source, sc.seed)
        self.ids = list(sc.ids)
        self.known = set(self.ids)
        self.step_s = sc.step_s
        self.ref_radius_m = sc.orbit.semi_major_axis_m
        self.model = LinkModel(self.cfg, self.ids, sc.step_s, LinkFaults(getattr(sc, "faults", None) or [], sc.ids, sc.step_s))
        self.inbox: list[list[Any]] = [[] for _ in self.ids]
        self._tx_seq = [0] * len(self.ids)   # each agent's seq on its isl/tx key
        self._rx_seq = [0] * len(self.ids)   # the channel's seq on each receiver's isl/rx key
        self.rejected = 0
        self.deliveries = 0

    def truth(self, ctx: SensingContext) -> None:
        a_m = getattr(ctx.world, "a_m", 0.0)
        self.model.set_truth(ctx.step, np.array(ctx.position_m, dtype=float), a_m if a_m > 0 else self.ref_radius_m)

    def take(self, rows: np.ndarray) -> list[list[Any]]:
        """The packets each observer has received since its last decision (its inbox, emptied)."""
        out = []
        for i in rows.tolist():
            out.append(self.inbox[i])
            self.inbox[i] = []
        return out

    def send(self, step: int, rows: np.ndarray, cb: CommandBatch) -> list[tuple[int, str]]:
        """The transmissions of the observers' commands of `step` (none from a command the agent
        replaces by zero: a non-finite acceleration or torque). Returns the ones `check_tx`
        rejects: (index into ids of the sender, the reason), in order."""
        t = step * self.step_s
        finite = np.isfinite(cb.accel_mps2).all(axis=1)  # (each row's test, for all rows at once)
        if cb.torque_nm is not None:
            finite &= np.isfinite(cb.torque_nm).all(axis=1)
        rejected: list[tuple[int, str]] = []
        for r, (i, ok) in enumerate(zip(rows.tolist(), finite.tolist())):
            if not ok:
                continue
            src = self.ids[i]
            for tx in cb.transmissions(r):
                seq = self._tx_seq[i]
                self._tx_seq[i] = seq + 1
                reason = check_tx(src, src, tx.dst, len(tx.payload), self.known, self.cfg.max_payload_bytes)
                if reason:
                    self.rejected += 1
                    rejected.append((i, reason))
                    continue
                self.model.submit(src, tx.dst, tx.type, tx.payload, seq, step, t)
        return rejected

    def window(self, step: int) -> list[tuple[int, RxPacket]]:
        """The deliveries of step `step`'s window into the receivers' inboxes: (index into ids of
        the receiver, the packet), in the order the channel publishes them."""
        return self._deliver(self.model.window(step))

    def finish(self, final_step: int) -> list[tuple[int, RxPacket]]:
        """The deliveries at the end of the run (the final tick at `final_step`: link/node.py `_finish`)."""
        return self._deliver(self.model.finish(final_step))

    def _deliver(self, out: list[Any]) -> list[tuple[int, RxPacket]]:
        index, inbox, rx_seq = self.model.index, self.inbox, self._rx_seq
        got = []
        for d in out:
            j = index[d.dst]
            seq = rx_seq[j]
            rx_seq[j] = seq + 1
            pkt = RxPacket(self, d.rx_step, seq, d.src, d.packet_dst, d.type, d.payload, d.send_t)
            inbox[j].append(pkt)
            got.append((j, pkt))
        self.deliveries += len(out)
        return got

    def summary(self) -> dict[str, Any]:
        tot = self.model.counters.totals()
        return {"config": self.cfg.to_dict(), "totals": {**tot, "rejected_packets": self.rejected},
                "pending_at_end": self.model.pending(), "deliveries": self.deliveries, "batch": True,
                # the counters per (src, dst, type), as the channel's summary has them (link/node.py)
                "link_columns": ["src", "dst", "type", *COUNTER_FIELDS],
                "links": [[s, d, t, *r] for s, d, t, r in self.model.counters.sorted_rows()]}


class BatchHook(LocalFlightSoftware):
    """The plant's `local_agents` (plant/flight.py): arrays of stimuli in, the (N, 3) commands in force out."""

    def __init__(self, bus: Any, run: str, sc: Any, recorder: Any = None) -> None:
        """`recorder`: the run's McapRecorder when it records every packet (deploy/batch_packets.py)."""
        from swarmhil.deploy.agent_image import agent_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

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
        self.link = BatchLink(run, sc) if channel_enabled(sc, {}) else None  # the channel's own test of [link]
        self.packets = None
        if recorder is not None:
            self.packets = BatchPackets(recorder, run, self.ids, [c.name for c in self.agents.controllers], sc.sensing["kind"])
            if self.link is not None:  # the channel's messages too, its first and final ones at the clock's ticks
                self.packets.link = LinkPackets(recorder, run, self.link)
                bus.subscribe(keys.clock, self._on_clock)
        # spacecraft that fly attitude: the commands go back with their torques, (N, 6) (plant/flight.py)
        self.attitude = any(sp.inertia_kgm2 is not None for sp in plant_config(sc).spacecraft)
        # the camera (`scene` stimulus, issue 36): each spacecraft's own perception, built as build_agent builds it
        self.perception = None
        if sc.sensing["kind"] == "scene":
            from swarmhil.agent.batch import BatchPerception  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
            from swarmhil.agent.perception import Perception  # scene sensing only: camera, navigation and scipy

            self.perception = BatchPerception(self.ids, [Perception(orbit.semi_major_axis_m, orbit.mean_motion_radps,
                                                                    c["nav"], c["camera"]) for c in cfgs],
                                              self.agents.faults)

    def commands(self, ctx: SensingContext, rows: np.ndarray,
                 sense: Callable[[], StimulusBatch | StimulusMessages]) -> np.ndarray:
        """`sense()` gives the stimuli of the observers `rows` (RelBatch, or the kind's messages); not
        called when no controller of the batch looks at its observation (`observes = False`,
        agent/controller.py). With a [link], the packets go through `BatchLink` around the decision."""
        ids = self.ids
        observers = ids if len(rows) == len(ids) else [ids[i] for i in rows.tolist()]
        link = self.link
        packets = self.packets
        if packets is not None:  # every packet recorded: the stimuli whether or not a controller looks
            t0 = time.perf_counter()
            rel = sense()
            decided = ctx.step % self.agents.decision_period_steps == 0 and len(rows) > 0
            obs = self._observe(ctx, rows, observers, lambda: rel)
            if link is not None:
                link.truth(ctx)
                if decided:
                    obs.isl_rx = link.take(rows)
            acc = self.agents.step(rows, obs)
            compute_s = (time.perf_counter() - t0) / max(len(rows), 1)  # each spacecraft's share
            rejected = None
            if link is not None and decided and self.agents.last is not None:
                rejected = link.send(ctx.step, rows, self.agents.last)
            packets.step(ctx.step, ctx.t_s, ctx.u_rad, rows, rel, self.agents, decided, compute_s, obs.neighbour_ids,
                         rejected)
            if link is not None and packets.link is not None:
                packets.link.window(ctx.step, link.window(ctx.step))
            return self._with_torques(acc) if self.attitude else acc
        if link is None:
            acc = self.agents.step(rows, self._observe(ctx, rows, observers, sense))
            return self._with_torques(acc) if self.attitude else acc
        link.truth(ctx)
        decide = ctx.step % self.agents.decision_period_steps == 0 and len(rows) > 0
        batch = self._observe(ctx, rows, observers, sense)
        if decide:
            batch.isl_rx = link.take(rows)
        acc = self.agents.step(rows, batch)
        if decide and self.agents.last is not None:
            link.send(ctx.step, rows, self.agents.last)
        link.window(ctx.step)
        return self._with_torques(acc)

    def _on_clock(self, _key: str, payload: bytes) -> None:
        """The plant's clock tick, just recorded: the link channel's messages that follow it."""
        if self.packets is not None and self.packets.link is not None:
            tick = pb.Tick.FromString(payload)
            self.packets.link.tick(int(tick.header.step), tick.header.t, tick.final)

    def close(self) -> None:
        """After the run (its `run_end` event): what the link channel writes when it closes."""
        if self.packets is not None and self.packets.link is not None:
            self.packets.link.close()

    def _with_torques(self, acc: np.ndarray) -> np.ndarray:
        return np.concatenate([acc, self.agents.torque_nm], axis=1) if self.attitude else acc

    def _observe(self, ctx: SensingContext, rows: np.ndarray, observers: list[str],
                 sense: Callable[[], StimulusBatch | StimulusMessages]) -> ObservationBatch:
        if self.perception is not None and len(rows):  # every frame, whether or not a controller looks (AgentNode)
            sb = sense()  # (plant/scene_stimulus.py SceneBatch)
            batch = self.perception.observe(ctx.step, ctx.t_s, ctx.u_rad, rows, observers, sb.offsets, sb.position_cam_m,
                                            sb.attitude_wxyz, self.agents.accel_mps2)
            if self.agents.observes:
                return batch
        if self.agents.observes and len(rows):
            rel = sense()
            if isinstance(rel, StimulusMessages):  # as the agent reads its stimulus message
                return ObservationBatch.of(observers, [observation_from_rel(m) for m in rel.messages])
            return ObservationBatch(step=ctx.step, t_s=ctx.t_s, u_rad=ctx.u_rad, observers=observers,
                                     offsets=rel.offsets,
                                     neighbour_ids=self._ids[rel.neighbour].tolist() if len(rel.neighbour) else [],
                                     rel_position_m=rel.rel_position_m, rel_velocity_mps=rel.rel_velocity_mps,
                                     owner=rel.owner, extra=getattr(rel, "extra", None))
        offsets, none = self._empty.get(len(rows), (None, None))
        if offsets is None:  # no neighbours for anyone: the same read-only arrays every step
            offsets, none = self._empty[len(rows)] = (np.zeros(len(rows) + 1, dtype=np.int64), np.zeros((0, 3)))
            offsets.setflags(write=False)
            none.setflags(write=False)
        return ObservationBatch(step=ctx.step, t_s=ctx.t_s, u_rad=ctx.u_rad, observers=observers,
                                offsets=offsets, neighbour_ids=[], rel_position_m=none, rel_velocity_mps=none)

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
        from swarmhil.dashboards.truth_io import TruthArrays, align_accel  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        k = self.k
        acc, recorded_as = align_accel(self.acc[:k].copy(), self.dv[:k], self.t_s[:k])
        return TruthArrays(run=run, ids=list(self.ids), step=self.step[:k].copy(), t_s=self.t_s[:k].copy(),
                           u_rad=self.u_rad[:k].copy(), semi_major_axis_m=self.a_m, mean_motion_radps=self.n_radps,
                           position_m=self.pos[:k].copy(), velocity_mps=self.vel[:k].copy(),
                           delta_v_mps=self.dv[:k].copy(), alive=self.alive[:k].copy(), accel_mps2=acc,
                           roe_m=self.roe[:k].copy(), accel_recorded_as=recorded_as)
