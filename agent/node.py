"""The flight-software process logic of one spacecraft: stimulus in, command and telemetry out.

Thin: everything it knows arrives as messages (it never imports plant); the decision is the
controller's (agent/controller.py). Bad input (undecodable, non-finite, foreign run, another
spacecraft's stimulus) is rejected and counted; the previous command stays in force.
"""
from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from swarmhil.agent.catalogue import make_controller
from swarmhil.agent.controller import Command, Observation, OrbitInfo
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.base import Bus
from swarmhil.bus.codec import RejectedPacket, Rejections, add_measurement, decode, header, measurements_to_dict, sense_type, vec
from swarmhil.bus.keys import Keys

log = logging.getLogger("swarmhil.agent")


def observation_from_rel(stim: pb.RelStimulus | pb.Measurements) -> Observation:
    """RelStimulus, or Measurements (neighbours plus named arrays in `extra`), as an Observation."""
    ids: list[str] = []
    rows_p: list[tuple[float, float, float]] = []
    rows_v: list[tuple[float, float, float]] = []
    for nb in stim.neighbours:  # one pass over the neighbours
        ids.append(nb.id)
        p, v = nb.position_m, nb.velocity_mps
        rows_p.append((p.x, p.y, p.z))
        rows_v.append((v.x, v.y, v.z))
    # one array from plain tuples (not one small array per neighbour): the same float64 values
    pos = np.array(rows_p, dtype=float).reshape(-1, 3)
    vel = np.array(rows_v, dtype=float).reshape(-1, 3)
    extra = measurements_to_dict(stim) if isinstance(stim, pb.Measurements) else {}
    return Observation(step=int(stim.header.step), t_s=stim.header.t, u_rad=stim.u_rad,
                       neighbour_ids=ids, rel_position_m=pos, rel_velocity_mps=vel, extra=extra)


def _finite(v: np.ndarray) -> bool:
    """np.all(np.isfinite(v)) of a small float array, on its Python floats (the same verdict)."""
    return all(map(math.isfinite, v.tolist()))


class AgentNode:
    def __init__(self, bus: Bus, run: str, sc_id: str, *, controller: str, orbit: OrbitInfo,
                 params: dict[str, Any], sense_kind: str = "rel", decision_period_steps: int = 1,
                 beacon: Any = None, perception: Any = None) -> None:
        self.bus = bus
        self.run = run
        self.id = sc_id
        self.keys = Keys(run)
        self.controller = make_controller(controller, sc_id, orbit, params)
        self.sense_kind = sense_kind
        self.decision_period_steps = max(1, decision_period_steps)
        self.rejections = Rejections(f"agent {sc_id}")
        self.command = Command(accel_mps2=np.zeros(3))
        self.steps = 0
        self.faults: dict[str, int] = {}  # "nav" / "controller": steps whose software raised (handled)
        self._seq: dict[str, int] = {}
        self._act_key = self.keys.act(sc_id)
        self._tm_key = self.keys.tm(sc_id)
        self._sense_key = self.keys.sense(sc_id, sense_kind)
        self._tx_key = self.keys.isl_tx(sc_id)
        self._rx_key = self.keys.isl_rx(sc_id)
        self.inbox: list[pb.IslPacket] = []
        self.beacon = beacon
        self.perception = perception
        if sense_kind == "scene" and perception is None:
            raise ValueError(f"{sc_id}: the scene stimulus needs a perception pipeline ([nav] table)")
        bus.subscribe(self._rx_key, self._on_isl)
        bus.subscribe(self._sense_key, self._on_stimulus)
        self._token = bus.declare_liveliness(self.keys.alive(f"agent-{sc_id}"))

    def _hdr(self, key: str, step: int, t: float) -> pb.Header:
        seq = self._seq.get(key, 0)
        self._seq[key] = seq + 1
        return header(self.run, self.id, step, t, seq)

    def _on_stimulus(self, key: str, payload: bytes) -> None:
        try:
            if key != self._sense_key:
                raise RejectedPacket(f"stimulus on {key!r} is not for {self.id}")
            stim = decode(sense_type(self.sense_kind), payload, run=self.run)
        except RejectedPacket as exc:
            self.rejections.add(key, str(exc))
            return
        self.handle(stim)

    def _on_isl(self, key: str, payload: bytes) -> None:
        try:
            pkt = decode(pb.IslPacket, payload, run=self.run)
            if pkt.dst not in ("", self.id):
                raise RejectedPacket(f"packet for {pkt.dst!r} delivered to {self.id}")
        except RejectedPacket as exc:
            self.rejections.add(key, str(exc))
            return
        self.inbox.append(pkt)

    def _transmit(self, step: int, t: float, tx: Any) -> None:
        self.bus.publish(self._tx_key, isl_packet(self._hdr(self._tx_key, step, t), self.id, tx, t).SerializeToString())

    def _publish_image(self, png: bytes, t: float) -> None:
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        img = CompressedImage(frame_id=f"{self.id}/camera", data=png, format="png")
        img.timestamp.seconds, img.timestamp.nanos = int(t), int(round((t - int(t)) * 1e9))
        self.bus.publish(self.keys.tm_image(self.id), img.SerializeToString())

    def _fault(self, where: str, step: int) -> None:
        """Count a handled software fault; the first of each kind is logged with its traceback."""
        n = self.faults[where] = self.faults.get(where, 0) + 1
        if n == 1:
            log.exception("%s: %s fault at step %d (handled; further ones are only counted)", self.id, where, step)
        else:
            log.warning("%s: %s fault #%d at step %d", self.id, where, n, step)

    def handle(self, stim: Any) -> None:
        t0 = time.perf_counter()
        step, t = int(stim.header.step), stim.header.t
        if self.perception is not None:  # camera frame -> blobs -> tracks, every frame
            try:
                obs = self.perception.observe(stim, self.command.accel_mps2)
            except Exception:  # noqa: BLE001 - a navigation fault must not stop the flight software
                self._fault("nav", step)
                self.perception.reset()  # restart navigation from the next frame (no tracks now)
                obs = Observation(step=step, t_s=t, u_rad=stim.u_rad, neighbour_ids=[],
                                  rel_position_m=np.zeros((0, 3)), rel_velocity_mps=np.zeros((0, 3)))
        if step % self.decision_period_steps == 0:
            if self.perception is None:
                obs = observation_from_rel(stim)
            obs.isl_rx, self.inbox = self.inbox, []
            try:
                cmd = self.controller.step(obs)
            except Exception:  # noqa: BLE001 - as above: command zero this step, count, go on
                self._fault("controller", step)
                cmd = Command(accel_mps2=np.zeros(3), mode="fault")
            a = np.asarray(cmd.accel_mps2, dtype=float)
            tq = None if cmd.torque_nm is None else np.asarray(cmd.torque_nm, dtype=float)
            if a.shape != (3,) or not _finite(a) or (tq is not None and (tq.shape != (3,) or not _finite(tq))):
                log.error("%s: controller %s returned accel %r, torque %r; commanding zero", self.id,
                          self.controller.name, a, tq)
                cmd = Command(accel_mps2=np.zeros(3), mode="fault")
            self.command = cmd
        compute_s = time.perf_counter() - t0
        # transmissions go out before the command: the channel knows step k's traffic is complete
        # once it has seen every live agent's command of step k (same session, same order)
        txs = list(self.command.transmissions) if step % self.decision_period_steps == 0 else []
        if self.beacon is not None:
            txs += self.beacon.emit(step, t, self.command)
        for tx in txs:
            self._transmit(step, t, tx)
        name = self.controller.name
        act = actuator_command(self._hdr(self._act_key, step, t), self.command, name, len(txs))
        self.bus.publish(self._act_key, act.SerializeToString())
        tm = telemetry(self._hdr(self._tm_key, step, t), self.command, name, compute_s, self.rejections.total)
        if self.perception is not None:
            tm.tracks.extend(self.perception.track_messages())
            png = self.perception.debug_image(t)
            if png is not None:
                self._publish_image(png, t)
        self.bus.publish(self._tm_key, tm.SerializeToString())
        self.steps += 1


def isl_packet(hdr: pb.Header, src: str, tx: Any, t: float) -> pb.IslPacket:
    """The IslPacket an agent publishes on its isl/tx key for a Transmission of its command."""
    return pb.IslPacket(header=hdr, src=src, dst=tx.dst, type=tx.type, payload=tx.payload, sent_t=t)


def actuator_command(hdr: pb.Header, cmd: Command, controller: str, isl_tx_count: int) -> pb.ActuatorCommand:
    """The ActuatorCommand an agent publishes for the command in force (torque where it has one)."""
    act = pb.ActuatorCommand(header=hdr, accel_mps2=vec(cmd.accel_mps2), controller=controller,
                             isl_tx_count=isl_tx_count)
    if cmd.torque_nm is not None:
        act.torque_nm.CopyFrom(vec(cmd.torque_nm))
    return act


def telemetry(hdr: pb.Header, cmd: Command, controller: str, compute_s: float, rejected_packets: int) -> pb.Telemetry:
    """The Telemetry an agent publishes for the command in force: mode, acceleration, its extra
    arrays (items) and decisions (the tracks of a perception are added by the caller, before the
    decisions: protobuf writes fields in number order)."""
    tm = pb.Telemetry(header=hdr, mode=cmd.mode, controller=controller, accel_mps2=vec(cmd.accel_mps2),
                      compute_s=compute_s, rejected_packets=rejected_packets)
    for name, values in cmd.extra.items():
        add_measurement(tm, name, values)
    add_decision = tm.decisions.add  # built in place (append would copy each message)
    for d in cmd.decisions:
        q = add_decision(neighbour=d.neighbour, behaviour=d.behaviour, d_min_m=float(d.d_min_m),
                         roe_rel_m=np.asarray(d.roe_rel_m, dtype=float).tolist()).accel_mps2
        q.x, q.y, q.z = np.asarray(d.accel_mps2, dtype=float).tolist()[:3]
    return tm
