"""Every packet of a batch run, recorded: what the agents and the plant would have sent, from the batch's arrays.

A batch run (deploy/batch.py) has no message between the plant and the flight software. With
`--record all` the recording still holds every packet the per-agent in-process run records, with
the same bytes and in the same order: per step, after the plant's tick, truth (and the Foxglove
transforms and scene the recorder derives from it) and events, for each live spacecraft in id
order its stimulus (`sc/<id>/sense/<kind>`), then its `act` and its `tm`, as the in-memory bus
delivers them when the plant publishes stimulus after stimulus and each agent answers at once.
The sensing kinds: `rel` (RelStimulus) and `relative` (Measurements with its own-state items;
with noise the kind hands its messages themselves, which are written as they are).

The messages are written from arrays (bus/bulk_wire.py): the stimuli from the step's `RelBatch`,
the commands and telemetry from the commands in force and, where the controllers give them
(`CommandBatch.decision_rows`), their decisions; a command that has more (transmissions, a torque,
extra arrays) or a decision step where a spacecraft's command was replaced by zero (its software
raised or commanded a non-finite value) is written through the agent's own message code
(agent/node.py `actuator_command`, `telemetry`), the same bytes. The recorder writes each step's
messages as one buffer (bus/recorder.py `write_many`) and learns the agents' modes for the Foxglove
scene as from their telemetry.

What differs from the per-agent run: `Telemetry.compute_s` is each spacecraft's share of the batch
decision's wall time (the batch decides for all at once), and a message's MCAP publish time (the
recorder's wall clock) is that of its step's buffer.
"""
from __future__ import annotations

import json
from typing import Any, Callable

import numpy as np

from swarmhil.agent.batch import BatchAgents
from swarmhil.agent.controller import Command
from swarmhil.agent.node import actuator_command, isl_packet, telemetry
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.bulk_wire import AgentMessages, Appended, IslPackets, Pool, Prepared, RelStimuli
from swarmhil.bus.codec import NamedRows, header, sense_type, sim_time_ns
from swarmhil.bus.keys import Keys
from swarmhil.bus.mcap_writer import BulkRecords
from swarmhil.bus.recorder import McapRecorder
from swarmhil.plant.flight import StimulusMessages


PACKET_KINDS = ("rel", "relative")  # sensing kinds whose stimuli a batch run writes (RelStimulus, Measurements)


_NO_ROWS = np.zeros(0, dtype=np.int64)  # a telemetry without decisions: its empty arrays
_NO_VALUES, _NO_ROE, _NO_VEC = np.zeros(0), np.zeros((0, 6)), np.zeros((0, 3))


def why_not_packets(sc: Any) -> str | None:
    """None when a batch run can record every packet (this module), else why not (one phrase): the
    stimuli of `rel`, `relative` and of the mission kinds that hand `Measurements` (their batch
    form's named arrays, or their messages themselves) are written; those of another kind (the
    camera's `scene`) are not."""
    from swarmhil.plant.sensing.registry import sensing_message  # on use: the kinds' registry loads them

    kind = sc.sensing["kind"]
    if kind not in PACKET_KINDS and sensing_message(kind) is not pb.Measurements:
        return f"every packet of sensing kind {kind!r} is recorded by the per-agent path"
    return None


class BatchPackets:
    """The stimuli, commands and telemetry of a batch run's spacecraft, written to the recorder
    step by step (module docstring)."""

    def __init__(self, rec: McapRecorder, run: str, ids: list[str], controllers: list[str], sense_kind: str = "rel") -> None:
        keys = Keys(run)
        self.rec = rec
        self.run = run
        self.ids = list(ids)
        n = len(self.ids)
        sense = [keys.sense(s, sense_kind) for s in self.ids]
        act, tm = [keys.act(s) for s in self.ids], [keys.tm(s) for s in self.ids]
        self._cids = np.array([rec.channels(sense, [sense_type(sense_kind)] * n), rec.channels(act, [pb.ActuatorCommand] * n),
                               rec.channels(tm, [pb.Telemetry] * n)]).T  # (N, 3): stimulus, act, tm of each
        self._all_cids = self._cids.ravel()
        self._seq_sense = np.zeros(n, dtype=np.uint64)  # the plant's seq on each sense key
        self._seq_agent = np.zeros(n, dtype=np.uint64)  # each agent's seq on its act and tm keys (one each a step)
        self._ctrl_names = list(controllers)
        pool = Pool()
        self.stimuli = RelStimuli(pool, run, "plant", self.ids)
        self.agents = AgentMessages(pool, run, self.ids, self._ctrl_names)
        self.tx = IslPackets(pool, run)
        self.records = BulkRecords(pool)
        self._keys = keys
        self._commands = [Command(accel_mps2=np.zeros(3)) for _ in self.ids]  # in force (the per-message path)
        self._seq_tx = [0] * n  # each agent's seq on its isl/tx key
        self._tx_cids: dict[int, int] = {}
        self.link: LinkPackets | None = None  # the link channel's messages, with a [link] (BatchHook sets it)
        self._rec_cids: dict[tuple[bytes, bool], np.ndarray] = {}  # `_record_channels`

    def step(self, step: int, t_s: float, u_rad: float, rows: np.ndarray, rel: Any, agents: BatchAgents,
             decided: bool, compute_s: float, neighbour_ids: list[str] | None = None,
             rejected: "list[tuple[int, str]] | None" = None) -> None:
        """Step `step`'s packets of the observers `rows` (indices into ids, increasing): their
        stimuli `rel` (RelBatch), and the commands in force in `agents` after this step's decision
        (`decided`: it was a decision step), each agent's telemetry reporting `compute_s`.
        `neighbour_ids`: the observation's list of the pairs' neighbour ids (the names of
        `rel.neighbour`), which decisions that name them may carry as they are. `rejected`: the
        transmissions of this step the link rejected (`BatchLink.send`), whose events the channel
        publishes after the sender's telemetry."""
        r = len(rows)
        if r == 0:
            return
        stim: Prepared | Appended | None = None
        if isinstance(rel, StimulusMessages):  # the kind's messages themselves (built with the plant's sequence numbers)
            stim_msgs = [m.SerializeToString() for m in rel.messages]
        else:
            extra = getattr(rel, "extra", None)
            stim = self.stimuli.prepare(step, t_s, self._seq_sense[rows], u_rad, rel.offsets, rel.neighbour,
                                        rel.rel_position_m, rel.rel_velocity_mps,
                                        extra.rows if isinstance(extra, NamedRows) else extra)
            self._seq_sense[rows] += np.uint64(1)
        seq = self._seq_agent[rows]
        self._seq_agent[rows] += np.uint64(1)
        acc = agents.accel_mps2 if r == len(self.ids) else agents.accel_mps2[rows]
        modes = agents.modes if r == len(self.ids) else [agents.modes[i] for i in rows.tolist()]
        cb = agents.last
        fast = (stim is not None and decided and cb is not None and cb.decision_rows is not None and not agents.replaced
                and agents.decision_period_steps == 1)
        if fast:
            d = cb.decision_rows
            parts = [stim,
                     self.agents.commands(step, t_s, seq, rows, acc),
                     self.agents.telemetry(step, t_s, seq, rows, modes, acc, compute_s, d.offsets,
                                           rel.neighbour if d.neighbour_ids is neighbour_ids else d.neighbour_ids,
                                           d.labels, d.behaviour, d.d_min_m, d.roe_rel_m, d.accel_mps2)]
            # per spacecraft: stimulus, act, tm (the order of the per-agent run), one buffer of records
            cids = self._all_cids if r == len(self.ids) else self._cids[rows].ravel()
            self.rec.write_records(self.records, parts, cids, sim_time_ns(t_s))
        else:
            if decided:
                self._take_commands(rows, agents)
            cmds = [self._commands[i] for i in rows.tolist()]
            if not rejected and all(c.torque_nm is None and not c.extra and not c.decisions for c in cmds):
                self._write_arrays(step, t_s, rows, seq, stim if stim is not None else _joined(stim_msgs), cmds,
                                   decided, compute_s)
                cmds = []
            else:
                blob, e = stim.encode() if stim is not None else _joined(stim_msgs)
            by_sender: dict[int, list[str]] = {}
            for i, reason in rejected or ():
                by_sender.setdefault(i, []).append(reason)
            if cmds:
                self._write_messages(step, t_s, rows, seq, blob, e, decided, compute_s, by_sender)
        scene = self.rec.scene
        if scene is not None:
            scene.saw_modes(self.ids if r == len(self.ids) else [self.ids[i] for i in rows.tolist()], modes)

    def on_truth(self, ids: list[str], then: Callable[..., None] | None = None) -> Callable[..., None]:
        """A plant's `on_truth` (plant/node.py) that hands the recorder the bodies of the truth it is
        about to publish (`McapRecorder.next_truth`: the Foxglove scene from the arrays), then calls
        `then` (a TruthLog) with the same arguments."""
        kinds = ["spacecraft"] * len(ids)  # (the kind bus/truth_wire.py writes for every body)

        def hook(step: int, t_s: float, u_rad: float, pos: np.ndarray, *rest: Any) -> None:
            self.rec.next_truth = (ids, kinds, rest[2].tolist(), pos)  # rest: vel, delta_v, alive, accel, roe
            if then is not None:
                then(step, t_s, u_rad, pos, *rest)

        return hook

    def _take_commands(self, rows: np.ndarray, agents: BatchAgents) -> None:
        """The Commands in force after a decision of `rows`: each one's own, zero (mode fault) where
        the agent replaced it (agent/node.py AgentNode.handle)."""
        cb = agents.last
        assert cb is not None
        replaced = set(agents.replaced)
        for r, i in enumerate(rows.tolist()):
            self._commands[i] = Command(accel_mps2=np.zeros(3), mode="fault") if r in replaced else cb.command(r)

    def _write_arrays(self, step: int, t_s: float, rows: np.ndarray, seq: np.ndarray,
                      stim: "Prepared | Appended | tuple[bytes, np.ndarray]", cmds: list[Command], decided: bool,
                      compute_s: float) -> None:
        """`_write_messages` of Commands in force that hold an acceleration, a mode and transmissions
        only (no torque, extra arrays or decisions: papers 001, 003 and 004), from arrays: the
        transmissions (bus/bulk_wire.py IslPackets), commands and telemetry each one encoder's
        gather, then one buffer in the per-agent order; where each spacecraft sent one packet (or
        none) and the stimuli are encoded too, the records of all in one gather (`BulkRecords`)."""
        r = len(rows)
        acc = np.array([c.accel_mps2 for c in cmds], dtype=float).reshape(r, 3)
        modes = [c.mode for c in cmds]
        txs = [list(c.transmissions) for c in cmds] if decided else [[] for _ in cmds]
        counts = [len(x) for x in txs]
        n_tx = sum(counts)
        act = self.agents.commands(step, t_s, seq, rows, acc, np.array(counts) if n_tx else None)
        tm = self.agents.telemetry(step, t_s, seq, rows, modes, acc, compute_s, np.zeros(r + 1, dtype=np.int64),
                                   _NO_ROWS, (), _NO_ROWS, _NO_VALUES, _NO_ROE, _NO_VEC)
        tx: Prepared | None = None
        if n_tx:
            srcs, seqs, flat = [], [], []
            for i, x in zip(rows.tolist(), txs):
                if x:
                    k = self._seq_tx[i]
                    self._seq_tx[i] = k + len(x)
                    srcs += [self.ids[i]] * len(x)
                    seqs += range(k, k + len(x))
                    flat += x
            tx = self.tx.prepare(step, t_s, seqs, srcs, srcs, [x.dst for x in flat], [x.type for x in flat],
                                 [x.payload for x in flat], [t_s] * n_tx)
        if isinstance(stim, Prepared) and n_tx in (0, r):  # one gather of the records: stimulus, [packet,] act, tm
            parts = [stim, act, tm] if tx is None else [stim, tx, act, tm]
            self.rec.write_records(self.records, parts, self._record_channels(rows, tx is not None), sim_time_ns(t_s))
            return
        stim_b, s_ends = stim if isinstance(stim, tuple) else stim.encode()
        act_b, act_e = act.encode()
        tm_b, tm_e = tm.encode()
        se, ae, me = s_ends.tolist(), act_e.tolist(), tm_e.tolist()
        tx_b, te = b"", [0]
        if tx is not None:
            tx_b, tx_e = tx.encode()
            te = tx_e.tolist()
        t0, a0 = len(stim_b), len(stim_b) + len(tx_b)
        m0 = a0 + len(act_b)
        starts: list[int] = []
        ends: list[int] = []
        cids: list[int] = []
        k = 0
        for j, (i, c) in enumerate(zip(rows.tolist(), counts)):  # per spacecraft: stimulus, transmissions, act, tm
            starts.append(se[j])
            ends.append(se[j + 1])
            cids.append(int(self._cids[i, 0]))
            if c:
                tx_cid = self._tx_channel(i)
                starts += [t0 + x for x in te[k:k + c]]
                ends += [t0 + x for x in te[k + 1:k + c + 1]]
                cids += [tx_cid] * c
                k += c
            starts += [a0 + ae[j], m0 + me[j]]
            ends += [a0 + ae[j + 1], m0 + me[j + 1]]
            cids += [int(self._cids[i, 1]), int(self._cids[i, 2])]
        a_s, a_e = np.array(starts, dtype=np.int64), np.array(ends, dtype=np.int64)
        blob = b"".join((stim_b, tx_b, act_b, tm_b))
        if self.link is not None:  # (written with the link's window: one write a step)
            self.link.hold(cids, blob, a_s, a_e - a_s, t_s)
        else:
            self.rec.write_many(cids, blob, a_s, a_e - a_s, sim_time_ns(t_s))

    def _write_messages(self, step: int, t_s: float, rows: np.ndarray, seq: np.ndarray, stim: bytes,
                        s_ends: np.ndarray, decided: bool, compute_s: float, rejected: dict[int, list[str]]) -> None:
        """Each spacecraft's stimulus, transmissions, command and telemetry through the agent's own
        message code (agent/node.py), from its Command in force, written in order; after a sender's
        telemetry, the link's events of its `rejected` transmissions (`LinkPackets.rejected`)."""
        cids: list[int] = []
        msgs: list[bytes] = []
        t_ns = sim_time_ns(t_s)
        se = s_ends.tolist()
        for r, (i, q) in enumerate(zip(rows.tolist(), seq.tolist())):
            cmd, sid, name = self._commands[i], self.ids[i], self._ctrl_names[i]
            cids.append(int(self._cids[i, 0]))
            msgs.append(stim[se[r]:se[r + 1]])
            txs = list(cmd.transmissions) if decided else []
            if txs:
                tx_cid = self._tx_channel(i)
                for tx in txs:
                    k = self._seq_tx[i]
                    self._seq_tx[i] = k + 1
                    cids.append(tx_cid)
                    msgs.append(isl_packet(header(self.run, sid, step, t_s, k), sid, tx, t_s).SerializeToString())
            hdr = header(self.run, sid, step, t_s, q)
            cids += [int(self._cids[i, 1]), int(self._cids[i, 2])]
            msgs.append(actuator_command(hdr, cmd, name, len(txs)).SerializeToString())
            msgs.append(telemetry(hdr, cmd, name, compute_s, 0).SerializeToString())
            if i in rejected and self.link is not None:
                self._flush(cids, msgs, t_ns)
                cids, msgs = [], []
                for reason in rejected[i]:
                    self.link.rejected(self._keys.isl_tx(sid), sid, reason)
        self._flush(cids, msgs, t_ns)

    def _flush(self, cids: list[int], msgs: list[bytes], t_ns: int | None) -> None:
        if cids:
            blob, e = _joined(msgs)
            self.rec.write_many(cids, blob, e[:-1], e[1:] - e[:-1], t_ns)

    def _record_channels(self, rows: np.ndarray, with_tx: bool) -> np.ndarray:
        """The channels of `rows`' records, per spacecraft: stimulus, [isl/tx,] act, tm."""
        key = (rows.tobytes(), with_tx)
        got = self._rec_cids.get(key)
        if got is None:
            c = self._cids[rows]
            if with_tx:
                c = np.stack([c[:, 0], [self._tx_channel(i) for i in rows.tolist()], c[:, 1], c[:, 2]], axis=1)
            if len(self._rec_cids) >= 1024:
                self._rec_cids.clear()
            got = self._rec_cids[key] = np.ascontiguousarray(c).ravel()
        return got

    def _tx_channel(self, i: int) -> int:
        cid = self._tx_cids.get(i)
        if cid is None:
            cid = self._tx_cids[i] = self.rec.channels([self._keys.isl_tx(self.ids[i])], [pb.IslPacket])[0]
        return cid


def _joined(msgs: list[bytes]) -> tuple[bytes, np.ndarray]:
    ends = np.zeros(len(msgs) + 1, dtype=np.int64)
    np.cumsum([len(m) for m in msgs], out=ends[1:])
    return b"".join(msgs), ends


class LinkPackets:
    """What the link channel (link/node.py ChannelNode) publishes in a per-agent run, written from a
    batch run's `BatchLink` (deploy/batch.py), which feeds the channel's model as the channel does:

    - at the first clock tick, right after it, the `link_config` event (source "channel");
    - per step, after every live agent's packets: the window's deliveries (`isl/rx/<receiver>`,
      header step and time those of the receiving step), `link/stats` when `stats_period_s` of
      simulation time has passed since the last, and the lockstep barrier `sync/channel`;
    - after a sender's telemetry, a `rejected_packet` event for each of its transmissions
      `check_tx` rejects (at most `max_events`, all counted);
    - at the final tick, right after it, the last deliveries and statistics; after the run's end,
      statistics once more if they changed since (ChannelNode.close)."""

    NAME = "channel"  # (link/node.py NAME: the source of the channel's headers)

    def __init__(self, rec: McapRecorder, run: str, link: Any) -> None:
        keys = Keys(run)
        self.rec, self.run, self.link = rec, run, link
        self._k_event = keys.event
        self._rx_cids = rec.channels([keys.isl_rx(s) for s in link.ids], [pb.IslPacket] * len(link.ids))
        self._stats_cid, self._sync_cid = rec.channels([keys.link_stats, keys.sync(self.NAME)], [pb.LinkStats, pb.Tick])
        self._seq_event = self._seq_stats = self._seq_sync = 0
        self._next_stats_t = 0.0
        self._last_stats: tuple[dict[str, int], int] | None = None
        self.step, self.t = -1, 0.0  # the channel's step and time: the last clock tick's
        self.started = self.finished = False
        self._rejected = 0  # rejections so far (the channel's Rejections.total)
        self.rx = IslPackets(Pool(), run)
        self._parts: list[tuple[list[int], bytes, np.ndarray, np.ndarray, float]] = []  # the step's, not yet written

    def tick(self, step: int, t: float, final: bool) -> None:
        """The plant's clock tick of `step` (written just before): the channel's `_on_tick`."""
        if self.finished or (step <= self.step and not final):
            return
        if not self.started:
            self.started = True
            cfg = self.link.cfg
            self._event("link_config", self.NAME,
                        json.dumps({**cfg.to_dict(), "ids": self.link.ids, "step_s": self.link.step_s}))
        self.step, self.t = step, t
        if final:
            self.finished = True
            self._deliveries(self.link.finish(step))
            self._stats(step, t)
            self._flush()

    def hold(self, cids: list[int], blob: bytes, starts: np.ndarray, sizes: np.ndarray, t: float) -> None:
        """The agents' messages of the step (BatchPackets), written with the window's (`window`): one
        write of the step's messages."""
        self._parts.append((cids, blob, starts, sizes, t))

    def window(self, step: int, delivered: list[tuple[int, Any]]) -> None:
        """Step `step`'s window closed with `delivered` (BatchLink.window): deliveries, statistics when
        due, barrier (ChannelNode._close_window), written after what the step `hold`s."""
        self._deliveries(delivered)
        t = self.t
        if t + 1e-9 >= self._next_stats_t:
            self._stats(step, t)
            while self._next_stats_t <= t + 1e-9:
                self._next_stats_t += self.link.cfg.stats_period_s
        sync = pb.Tick(header=header(self.run, self.NAME, step, t, self._seq_sync), step_s=self.link.step_s)
        self._seq_sync += 1
        self._add([self._sync_cid], [sync.SerializeToString()], t)
        self._flush()

    def rejected(self, key: str, subject: str, reason: str) -> None:
        """A transmission `check_tx` rejected on `key` (ChannelNode._reject; BatchLink counts it)."""
        self._rejected += 1
        if self._rejected <= self.link.cfg.max_events:
            self._event("rejected_packet", subject, f"{key}: {reason}")

    def close(self) -> None:
        """After the run: the statistics once more if they changed since the last (ChannelNode.close)."""
        if self._last_stats != (self.link.model.counters.totals(), self.link.rejected):
            self._stats(max(self.step, 0), self.t)
            self._flush()

    def _deliveries(self, delivered: list[tuple[int, Any]]) -> None:
        """The IslPackets of one window (all of one receiving step: link/model.py `_take`)."""
        if delivered:
            step = delivered[0][1]._rx_step
            t = step * self.link.step_s  # (RxPacket.header's time)
            pk = [p for _j, p in delivered]
            blob, e = self.rx.prepare(step, t, [p._seq for p in pk], [self.NAME] * len(pk), [p.src for p in pk],
                                      [p.dst for p in pk], [p.type for p in pk], [p.payload for p in pk],
                                      [p.sent_t for p in pk]).encode()
            self._parts.append(([self._rx_cids[j] for j, _p in delivered], blob, e[:-1], e[1:] - e[:-1], t))
            scene = self.rec.scene
            if scene is not None:  # (the links the next truth's scene draws, as the recorder learns them from isl/rx)
                ids = self.link.ids
                for j, p in delivered:
                    scene.saw_delivery(p.src, ids[j])

    def _stats(self, step: int, t: float) -> None:
        model = self.link.model
        tot = model.counters.totals()
        st = pb.LinkStats(header=header(self.run, self.NAME, step, t, self._seq_stats), links=model.counters.to_pb(),
                          rejected_packets=self.link.rejected, tx_messages=tot["tx_messages"], rx_messages=tot["rx_messages"])
        self._seq_stats += 1
        self._add([self._stats_cid], [st.SerializeToString()], t)
        self._last_stats = (tot, self.link.rejected)

    def _add(self, cids: list[int], msgs: list[bytes], t: float) -> None:
        blob, e = _joined(msgs)
        self._parts.append((cids, blob, e[:-1], e[1:] - e[:-1], t))

    def _flush(self) -> None:
        """The parts so far, in order, as one write (each message at its own part's time)."""
        parts, self._parts = self._parts, []
        if not parts:
            return
        if len(parts) == 1:
            cids, blob, starts, sizes, t = parts[0]
            self.rec.write_many(cids, blob, starts, sizes, sim_time_ns(t))
            return
        at, cids, starts, times = 0, [], [], []
        for c, b, a, _z, t in parts:
            cids += c
            starts.append(np.asarray(a, dtype=np.int64) + at)
            times.append(np.full(len(c), sim_time_ns(t), dtype=np.int64))
            at += len(b)
        self.rec.write_many(cids, b"".join([b for _c, b, _a, _z, _t in parts]), np.concatenate(starts),
                            np.concatenate([np.asarray(z, dtype=np.int64) for _c, _b, _a, z, _t in parts]),
                            np.concatenate(times))

    def _event(self, kind: str, subject: str, detail: str) -> None:
        ev = pb.Event(header=header(self.run, self.NAME, max(self.step, 0), self.t, self._seq_event), kind=kind,
                      subject=subject, detail=detail)
        self._seq_event += 1
        self.rec.write(self._k_event, ev.SerializeToString())  # (decoded: the recorder writes its Foxglove log)
