"""The plant process logic: publish ticks, truth and stimuli; collect commands; propagate.

Thin: the physics is the world of the scenario's fidelity (plant/worlds.py), the stimuli
plant/sensors.py, the synchronisation plant/pacing.py. The node works the same over the Zenoh
bus (one process) and the in-memory bus (in-process batch runs).
"""
from __future__ import annotations

import json
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.base import Bus
from swarmhil.bus.codec import RejectedPacket, Rejections, command_rejection, decode, header, sim_time_ns
from swarmhil.bus.keys import Keys
from swarmhil.bus.truth_wire import HeaderEncoder, TickEncoder, TruthEncoder, body_entry
from swarmhil.plant.config import PlantConfig
from swarmhil.plant.contact import ContactMonitor
from swarmhil.plant.faults import ActuationFaults, SensingFaults, body_faults, fault_summary, transitions
from swarmhil.plant.flight import LocalFlightSoftware, StimulusMessages
from swarmhil.plant.mission_world import MissionWorld
from swarmhil.plant.pacing import CommandBox, Lockstep, Pacer, RealTime
from swarmhil.plant.sensing import SensingContext, make_sensing
from swarmhil.plant.world import World
from swarmhil.plant.worlds import make_world

log = logging.getLogger("swarmhil.plant")
REJECT_EVENTS_MAX = 1000  # Events "rejected_command" per run; summary.json counts every rejection


@dataclass
class PlantStats:
    dead_agents: dict[str, dict[str, Any]] = field(default_factory=dict)
    missed_deadlines: dict[str, int] = field(default_factory=dict)
    late_commands: int = 0
    steps: int = 0
    rejoins: list[dict[str, Any]] = field(default_factory=list)


class PlantNode:
    AGENT_PREFIX = "agent-"

    def __init__(self, bus: Bus, run: str, config: PlantConfig, *, expect_processes: tuple[str, ...] = ("recorder",),
                 barriers: tuple[str, ...] = (), progress: Callable[[int, float], None] | None = None,
                 local_agents: LocalFlightSoftware | None = None,
                 on_truth: Callable[..., None] | None = None) -> None:
        """`config`: the plant's configuration (plant/config.py; deploy/scenario.py `plant_config`
        builds it from a scenario)."""
        self.bus = bus
        self.keys = Keys(run)
        self._k_truth, self._k_clock = self.keys.truth, self.keys.clock  # (built once: keys of every step)
        self.run_id = run
        self.cfg = config
        # the truth model the fidelity names (plant/worlds.py: World for linear / j2, MissionWorld for cw / inertial)
        self.world: World | MissionWorld = make_world(config)
        self.step_s = config.step_s
        self.pacer: Pacer = (Lockstep(config.stall_timeout_s) if config.mode == "lockstep"
                             else RealTime(config.step_s, config.speed))
        self.box = CommandBox()
        self.rejections = Rejections("plant")
        self.stats = PlantStats()
        self.expect_processes = tuple(expect_processes) + tuple(b for b in barriers if b not in expect_processes)
        self.barriers = tuple(barriers)
        self.progress = progress
        self.present: set[str] = set()      # processes whose liveliness token is up
        self.seen_alive: set[str] = set()   # agents that were up once
        self._rejoin: set[str] = set()      # dead agents whose token is back: alive again at the next step
        self.held = np.zeros((len(config.ids), 6))  # last command (accel, torque) of each spacecraft, held on a miss
        self._seq: dict[str, int] = {}
        self._seq_lock = threading.Lock()
        self._step = 0
        self.timing: dict[str, float] = {}
        self._sense_keys = [self.keys.sense(sid, config.sensing["kind"]) for sid in config.ids]
        self._act_ids = {self.keys.act(sid): sid for sid in config.ids}  # a command's key -> its spacecraft
        self.sensor = make_sensing(config.sensing["kind"], config)
        # [[fault]] (issue 27, plant/faults.py): actuator faults act in the world's actuator model,
        # sensing faults on the stimuli; each fault's start and end is an Event on `faults`
        self._faults = list(config.faults)
        self._sensing_faults: SensingFaults | None = None
        self._paused: set[str] = set()  # agents a process_pause fault holds out of the lockstep
        if self._faults:
            actuation = ActuationFaults(self._faults, list(config.ids), config.step_s)
            if actuation:
                self.world.actuation_faults = actuation
            if hasattr(self.world, "body_faults"):  # the mission world: bodies (a target's manoeuvre or spin change)
                self.world.body_faults = body_faults(self._faults, config.step_s)
            sensing = SensingFaults(self._faults, list(config.ids), config.step_s, config.seed)
            self._sensing_faults = sensing if sensing else None
        # hulls (issue 27, plant/contact.py): a contact or near-miss Event when two hulls touch or
        # come within the keep-out distance
        self.contact = ContactMonitor.of(config)
        # batch mode (issue 16): the flight software of every spacecraft in this process, through the
        # plant's interface (plant/flight.py; deploy/batch.py implements it), called with the sensing
        # kind's stimuli as arrays (`batch`, computed when it calls `sense()`) instead of one message
        # per spacecraft; returns the (N, 3) commands, which stand for the live agents' answers
        self.local_agents = local_agents
        self._local_cmd: np.ndarray | None = None
        self._local_all = False  # every spacecraft alive at the step of _local_cmd
        self._all_rows = np.arange(len(config.ids))  # the observers when all are alive
        self._all_rows.setflags(write=False)
        # on_truth(step, t_s, u_rad, position, velocity, delta_v, alive, accel_cmd, roe): the values
        # of every truth the ROE plants publish, for a caller in this process that keeps them as
        # arrays (deploy/batch.TruthLog: a campaign's metrics without reading the recording back)
        self.on_truth = on_truth
        # the truth of the ROE plants, and of a mission world without attitude or bodies (the same
        # fields), written without building the message (bus/truth_wire.py: the same bytes); on an
        # in-process bus, samples stamped with their simulation time, and the tick built only when
        # someone receives it (bus/memory.py)
        plain = isinstance(self.world, World) or (isinstance(self.world, MissionWorld) and self.world.attitude is None
                                                  and not self.world.bodies)
        # a mission world without attitude but with bodies: its spacecraft through the encoder too, and
        # each body's entry after them the bytes of its own message (`_body_state`)
        self._truth_bodies = (isinstance(self.world, MissionWorld) and self.world.attitude is None
                              and bool(self.world.bodies))
        self._truth_wire = TruthEncoder(self.world.ids) if plain or self._truth_bodies else None
        self._truth_header = HeaderEncoder(run, "plant")
        self._tick = TickEncoder(run, list(self.world.ids))  # (the same bytes as pb.Tick's)
        self._stamps = bool(getattr(bus, "stamps", False))
        self._wants = getattr(bus, "wants", None)
        bus.subscribe(self.keys.act_all, self._on_command)
        if self.barriers:
            bus.subscribe(self.keys.sync_all, self._on_barrier)
        bus.watch_liveliness(self.keys.alive_all, self._on_liveliness)
        self._token = bus.declare_liveliness(self.keys.alive("plant"))

    # --- bus callbacks (dispatcher thread) -------------------------------------------------
    def _on_liveliness(self, key: str, alive: bool) -> None:
        proc = key.rsplit("/", 1)[-1]
        if alive:
            self.present.add(proc)
            if proc.startswith(self.AGENT_PREFIX):
                sc = proc[len(self.AGENT_PREFIX):]
                self.seen_alive.add(sc)
                if sc in self.stats.dead_agents and sc in self.world.index:
                    self._rejoin.add(sc)  # restarted, or resumed after a pause longer than its lease
        else:
            self.present.discard(proc)
            sc = proc[len(self.AGENT_PREFIX):] if proc.startswith(self.AGENT_PREFIX) else None
            self._rejoin.discard(sc)
            if sc in self.world.index and self.world.alive[self.world.index[sc]]:
                self._mark_dead(sc, "liveliness token disappeared")
        self.box.wake()

    def _on_command(self, key: str, payload: bytes) -> None:
        cmd = None
        try:
            sc = self._act_ids.get(key)
            if sc is None:
                _kind, sc, _ = self.keys.parse(key)
                if sc not in self.world.index:
                    raise RejectedPacket(f"unknown spacecraft id {sc!r}")
            cmd = decode(pb.ActuatorCommand, payload)
            why = command_rejection(cmd, sc, self.run_id)
            if why:
                raise RejectedPacket(why)
        except (RejectedPacket, ValueError) as exc:
            self._reject_command(key, str(exc), cmd)
            return
        a, tq = cmd.accel_mps2, cmd.torque_nm  # (np.concatenate of the two `arr`: the same six float64)
        if not self.box.put(int(cmd.header.step), sc, np.array([a.x, a.y, a.z, tq.x, tq.y, tq.z])):
            self.stats.late_commands += 1

    def _reject_command(self, key: str, reason: str, cmd: Any) -> None:
        """A command the plant does not act on: counted (summary.json rejected_packets) and, for the
        first REJECT_EVENTS_MAX, an Event "rejected_command" whose subject is the spacecraft of the
        key and whose detail (JSON) gives the key, the reason and what the command claimed (source,
        run, step; empty when it did not decode)."""
        self.rejections.add(key, reason)
        if self.rejections.total <= REJECT_EVENTS_MAX:
            hdr = cmd.header if cmd is not None else None
            self._event("rejected_command", key.rsplit("/", 2)[-2], json.dumps(
                {"key": key, "reason": reason, "claimed_source": hdr.source if hdr else "",
                 "claimed_run": hdr.run if hdr else "", "claimed_step": int(hdr.step) if hdr else None}))

    def _on_barrier(self, key: str, payload: bytes) -> None:
        try:
            _kind, proc, _ = self.keys.parse(key)
            if proc not in self.barriers:
                raise RejectedPacket(f"unknown lockstep participant {proc!r}")
            tick = decode(pb.Tick, payload, run=self.run_id)
        except (RejectedPacket, ValueError) as exc:
            self.rejections.add(key, str(exc))
            return
        self.box.put(int(tick.header.step), f"sync:{proc}", None)

    def _expected(self) -> set[str]:
        return self.live_ids() | {f"sync:{b}" for b in self.barriers if b in self.present}

    # --- helpers ----------------------------------------------------------------------------
    def _next_seq(self, key: str) -> int:
        with self._seq_lock:  # events also go out from the command callback (rejected commands)
            seq = self._seq.get(key, 0)
            self._seq[key] = seq + 1
        return seq

    def _hdr(self, key: str) -> pb.Header:
        return header(self.run_id, "plant", self._step, self.world.t_s, self._next_seq(key))

    def _event(self, kind: str, subject: str, detail: str) -> None:
        ev = pb.Event(header=self._hdr(self.keys.event), kind=kind, subject=subject, detail=detail)
        self.bus.publish(self.keys.event, ev.SerializeToString())
        (log.info if kind.startswith("run_") else log.warning)("%s %s: %s", kind, subject, detail)

    def _fault_events(self, final: bool) -> None:
        """Each [[fault]] that starts or ends at this step: an Event on `faults` (kind fault_start or
        fault_end, subject the fault's name, detail its table as JSON)."""
        for kind, f in transitions(self._faults, self.step_s, self._step, final):
            detail = json.dumps(fault_summary(f))
            ev = pb.Event(header=self._hdr(self.keys.faults), kind=kind, subject=f.name, detail=detail)
            self.bus.publish(self.keys.faults, ev.SerializeToString())
            log.info("%s %s: %s", kind, f.name, detail)  # scheduled: the run does what it was asked
            if f.family == "process" and not final:
                self._process_fault(kind, f)

    def _process_fault(self, kind: str, f: Any) -> None:
        """A process fault at this step (the launcher acts on the process when it sees the event):
        a crash makes the agent dead now; a pause takes it out of the lockstep for the window (its
        spacecraft coasts) and back at the window's end if its liveliness token is still up."""
        for sc in f.targets:
            i = self.world.index[sc]
            if f.kind == "process_crash":
                if kind == "fault_start":
                    self._mark_dead(sc, f"fault {f.name}: process_crash at step {self._step}")
            elif kind == "fault_start" and self.world.alive[i]:
                self.world.alive[i] = False
                self._paused.add(sc)
                self._event("agent_paused", sc, f"fault {f.name}: paused at step {self._step}")
            elif kind == "fault_end" and sc in self._paused:
                self._paused.discard(sc)
                if self.AGENT_PREFIX + sc in self.present or self.local_agents is not None:
                    self.world.alive[i] = True
                    self.held[i] = 0.0
                    self._event("agent_resumed", sc, f"fault {f.name}: resumed at step {self._step}")
                else:
                    self.world.alive[i] = True  # (so that it is marked dead, with the reason)
                    self._mark_dead(sc, f"fault {f.name}: its liveliness token is gone at the end of its pause")

    def _mark_dead(self, sc: str, reason: str) -> None:
        i = self.world.index[sc]
        if not self.world.alive[i]:
            return
        self.world.alive[i] = False
        self.stats.dead_agents[sc] = {"step": self._step, "t_s": self.world.t_s, "reason": reason}
        self._event("agent_dead", sc, reason)

    def _apply_rejoins(self) -> None:
        """Between steps (main loop): a dead agent whose liveliness token is back rejoins cold at
        this step: the plant sends it this step's stimulus (the current state) and waits for its
        command again; it has coasted with no command since it died."""
        for sc in sorted(self._rejoin):
            self._rejoin.discard(sc)
            i = self.world.index[sc]
            if self.world.alive[i] or self.AGENT_PREFIX + sc not in self.present:
                continue
            dead = self.stats.dead_agents.pop(sc, {})
            self.world.alive[i] = True
            self.held[i] = 0.0
            self.stats.rejoins.append({"id": sc, "step": self._step, "t_s": self.world.t_s,
                                       "dead_step": dead.get("step"), "dead_reason": dead.get("reason")})
            self._event("agent_rejoin", sc, f"rejoined cold at step {self._step} (dead since step {dead.get('step')}: "
                                            f"{dead.get('reason')})")

    def live_ids(self) -> set[str]:
        return {sid for sid, a in zip(self.world.ids, self.world.alive) if a}

    def wait_ready(self, timeout_s: float = 600.0, should_stop: "Callable[[], bool] | None" = None) -> None:
        """Wait for every agent's and expected process's liveliness token before step 0 (or until
        should_stop(): the launcher stopped the run, or is gone)."""
        want = {self.AGENT_PREFIX + s for s in self.world.ids} | set(self.expect_processes)
        t_end = time.monotonic() + timeout_s
        while not want <= self.present:
            if should_stop is not None and should_stop():
                return
            if time.monotonic() > t_end:
                missing = sorted(want - self.present)
                raise TimeoutError(f"processes not up after {timeout_s:.0f} s: {missing[:10]}")
            time.sleep(0.01)

    # --- the loop -----------------------------------------------------------------------------
    def publish_step(self, final: bool = False) -> None:
        """Tick, truth and stimuli of the current step (arrays turned into lists once: numpy
        scalar access per field costs more than the rest of the step)."""
        k = self._step
        final = final or k >= self.cfg.steps
        if self._faults:
            self._fault_events(final)
        u = self.world.u_rad
        pos, vel = self.world.lvlh()
        ids = self.world.ids
        alive = self.world.alive.tolist()
        if self._wants is None or self._wants(self._k_clock):
            t_tick = self.world.t_s
            tick = self._tick.encode(k, t_tick, self._next_seq(self._k_clock), self.step_s, u, self.world.alive, final)
            if self._stamps:
                self.bus.publish(self._k_clock, tick, sim_time_ns(t_tick))
            else:
                self.bus.publish(self._k_clock, tick)
        # truth of step k goes out before the stimuli, so the link channel knows where everyone is
        # at the time agents transmit in step k
        t_s = self.world.t_s
        if self._truth_wire is not None:
            w = self.world
            roe = w.roe_m((pos, vel))
            bodies = b"".join(body_entry(self._body_state(bt).SerializeToString())
                              for bt in w.body_truth()) if self._truth_bodies else b""
            data = self._truth_wire.encode(self._truth_header(k, t_s, self._next_seq(self._k_truth)),
                                           u, w.a_m, w.n_radps, pos, vel, w.delta_v_mps, w.alive,
                                           w.last_accel_mps2, roe, bodies)
            if self.on_truth is not None and not self._truth_bodies:
                self.on_truth(k, t_s, u, pos, vel, w.delta_v_mps, w.alive, w.last_accel_mps2, roe)
        else:
            data = self._mission_truth(pos, vel, alive).SerializeToString()
        if self._stamps:
            self.bus.publish(self._k_truth, data, sim_time_ns(t_s))
        else:
            self.bus.publish(self._k_truth, data)
        bodies = self.world.body_truth() if isinstance(self.world, MissionWorld) and self.world.bodies else []
        for kind, pair, detail in self.contact.check(k, t_s, pos, bodies):
            self._event(kind, pair, detail)
        if final:
            return
        everyone = all(alive)
        ctx = SensingContext(step=k, t_s=self.world.t_s, u_rad=u, ids=ids, position_m=pos, velocity_mps=vel,
                             alive=self.world.alive, world=self.world, all_alive=everyone)
        if self.local_agents is not None:
            self._local_all = everyone
            rows = self._all_rows if self._local_all else np.flatnonzero(self.world.alive)
            if hasattr(self.sensor, "batch"):
                self._local_cmd = self.local_agents.commands(ctx, rows, lambda: self.sensor.batch(ctx, rows))
            else:  # a kind without a batch form: its messages, as they would have been published
                self._local_cmd = self.local_agents.commands(ctx, rows, lambda: self._stimulus_messages(ctx, rows))
            return
        stimuli = getattr(self.sensor, "stimuli", None)
        if stimuli is not None and self._sensing_faults is None:  # a kind that builds all its messages at once
            live = [j for j, a in enumerate(alive) if a]
            keys = [self._sense_keys[j] for j in live]
            for key, stim in zip(keys, stimuli(ctx, live, [self._hdr(key) for key in keys])):
                self.bus.publish(key, stim.SerializeToString())
            return
        for j, sid in enumerate(ids):
            if not alive[j]:
                continue
            key = self._sense_keys[j]
            stim = self.sensor.stimulus(ctx, j, self._hdr(key))
            if self._sensing_faults is not None:
                stim = self._sensing_faults.apply(stim, j, ctx)
            self.bus.publish(key, stim.SerializeToString())

    def _stimulus_messages(self, ctx: SensingContext, rows: np.ndarray) -> StimulusMessages:
        """The stimuli of the observers `rows` as the message path builds them (batch mode, a sensing
        kind without a batch form)."""
        return StimulusMessages([self.sensor.stimulus(ctx, j, self._hdr(self._sense_keys[j])) for j in rows.tolist()])

    def _mission_truth(self, pos: np.ndarray, vel: np.ndarray, alive: list[bool]) -> pb.Truth:
        """The truth message of the mission world (attitude, bodies): built field by field."""
        w = self.world
        truth = pb.Truth(header=self._hdr(self.keys.truth), u_rad=w.u_rad, semi_major_axis_m=w.a_m,
                         mean_motion_radps=w.n_radps)
        P, V, R, DV = pos.tolist(), vel.tolist(), w.roe_m().tolist(), w.delta_v_mps.tolist()
        A = w.last_accel_mps2.tolist()
        add = truth.bodies.add
        for sid, dv, al, r, p, v, a in zip(w.ids, DV, alive, R, P, V, A):  # each sub-message looked up once
            b = add(id=sid, kind="spacecraft", delta_v_mps=dv, alive=al, roe_m=r)
            q = b.position_m
            q.x, q.y, q.z = p
            q = b.velocity_mps
            q.x, q.y, q.z = v
            q = b.accel_cmd_mps2
            q.x, q.y, q.z = a
        self._add_mission_truth(truth)
        return truth

    def _add_mission_truth(self, truth: pb.Truth) -> None:
        """Attitude of the spacecraft that fly it, and every non-agent body (kind, pose)."""
        q, w = self.world.attitude_wxyz()
        if q is not None:
            tau = self.world.last_torque_nm
            for i in self.world.att_index.tolist():
                b = truth.bodies[i]
                b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z = q[i].tolist()
                b.angular_velocity_radps.x, b.angular_velocity_radps.y, b.angular_velocity_radps.z = w[i].tolist()
                b.torque_cmd_nm.x, b.torque_cmd_nm.y, b.torque_cmd_nm.z = tau[i].tolist()
        for bt in self.world.body_truth():
            self._body_state(bt, truth.bodies.add())

    @staticmethod
    def _body_state(bt: Any, b: pb.BodyState | None = None) -> pb.BodyState:
        """A non-agent body's entry of the truth (kind, pose), filled into `b` (None: a new message)."""
        b = pb.BodyState() if b is None else b
        b.id, b.kind, b.alive = bt.spec.id, bt.spec.kind, True
        b.position_m.x, b.position_m.y, b.position_m.z = bt.position_m.tolist()
        b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z = bt.velocity_mps.tolist()
        b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z = bt.attitude_q.tolist()
        w_ = bt.angular_velocity_radps
        b.angular_velocity_radps.x, b.angular_velocity_radps.y, b.angular_velocity_radps.z = w_.tolist()
        return b

    def collect_and_advance(self) -> None:
        """Wait for step k's commands and barriers, then propagate. Lockstep waits for every live
        process however slow it is: only a vanished liveliness token (dead: dropped at once, the
        wait re-evaluates) or the stall timeout ends the wait; a stall is an error event and drops
        the agents it waited for. Real time: what missed the wall deadline is held."""
        k = self._step
        if self._local_cmd is not None:  # batch mode: every live agent answered, in this process
            cmd, self._local_cmd = self._local_cmd, None
            if self._local_all and isinstance(self.world, World):  # everyone alive: the same assignments without the masks
                self.held[:, :3] = cmd
                self.held[:, 3:] = 0.0
                self.world.step(cmd, self.step_s, all_alive=True)  # (the values of held[:, :3], contiguous)
                self._after_step(k)
                return
            if self._local_all:  # (a mission world) everyone alive: the same assignments without the masks
                self.held[:, :cmd.shape[1]] = cmd
                if cmd.shape[1] == 3:
                    self.held[:, 3:] = 0.0
                self._advance(k, all_alive=True)
                return
            alive = self.world.alive
            if cmd.shape[1] == 6:  # accelerations and torques (spacecraft that fly attitude)
                self.held[alive] = cmd[alive]
            else:
                self.held[alive, :3] = cmd[alive]
                self.held[alive, 3:] = 0.0
            self._advance(k)
            return
        live = self.live_ids()
        got = self.box.wait(self._expected, self.pacer.deadline(k))
        lockstep = self.pacer.name == "lockstep"
        missing = sorted(self._expected() - got.keys())
        if lockstep and missing:
            self._event("lockstep_stall", "plant", f"step {k}: no command or barrier from {missing[:10]} within "
                                                   f"the stall timeout ({self.cfg.stall_timeout_s:.0f} s wall); "
                                                   f"agents among them are dropped")
        for b in self.barriers:
            if f"sync:{b}" not in got and not lockstep:
                self._event("deadline_missed", b, f"no lockstep barrier for step {k}")
        for sid in sorted(live):
            i = self.world.index[sid]
            if sid in got:
                self.held[i] = got[sid]
            elif self.world.alive[i]:
                self.stats.missed_deadlines[sid] = self.stats.missed_deadlines.get(sid, 0) + 1
                if lockstep:
                    self._mark_dead(sid, f"lockstep stall: no command for step {k} within {self.cfg.stall_timeout_s:.0f} s "
                                         f"while its liveliness token was up")
                else:
                    self._event("deadline_missed", sid, f"no command for step {k}; holding the previous one")
        self._advance(k)

    def _advance(self, k: int, all_alive: bool = False) -> None:
        if not all_alive:
            self.held[~self.world.alive] = 0.0
        if isinstance(self.world, MissionWorld):
            self.world.step(self.held[:, :3], self.step_s, self.held[:, 3:], all_alive=all_alive)
        else:
            self.world.step(self.held[:, :3], self.step_s, all_alive=all_alive)
        self._after_step(k)

    def _after_step(self, k: int) -> None:
        self.pacer.after_step(k)
        self._step += 1
        self.stats.steps = self._step

    def run(self, should_stop: Callable[[], bool] = lambda: False) -> dict[str, Any]:
        """Run every step (or until should_stop() is true: the run then ends early, cleanly)."""
        self._event("run_start", "plant", json.dumps({"agents": len(self.world.ids), "steps": self.cfg.steps, "mode": self.cfg.mode}))
        self.pacer.start()
        wall0 = time.monotonic()
        t_pub = t_loop = 0.0
        for k in range(self.cfg.steps):
            if should_stop():
                self._event("run_stopped", "plant", f"stopped at step {k} of {self.cfg.steps}")
                break
            if self._rejoin:
                self._apply_rejoins()
            if self.local_agents is None:  # (the batch mode's commands come back from local_agents)
                self.box.open(k)
            c0 = time.perf_counter()
            self.publish_step()
            c1 = time.perf_counter()
            self.collect_and_advance()
            t_pub += c1 - c0
            t_loop += time.perf_counter() - c0
            if self.progress:
                self.progress(self._step, time.monotonic() - wall0)
        self.publish_step(final=True)  # final tick + truth at t_end
        self.timing = {"loop_wall_s": t_loop, "publish_s": t_pub, "wait_and_propagate_s": t_loop - t_pub,
                       "propagate_s": self.world.wall_s}
        self._event("run_end", "plant", f"{self._step} steps")
        return self.summary()

    def summary(self) -> dict[str, Any]:
        return {
            "steps": self.stats.steps,
            "loop_wall_s": self.timing.get("loop_wall_s", 0.0),
            "plant_timing_s": self.timing,
            "delta_v_mps": {s: float(v) for s, v in zip(self.world.ids, self.world.delta_v_mps)},
            "delta_v_total_mps": float(self.world.delta_v_mps.sum()),
            "dead_agents": self.stats.dead_agents,
            "rejoins": self.stats.rejoins,
            "missed_deadlines": self.stats.missed_deadlines,
            "late_commands": self.stats.late_commands,
            "rejected_packets": {"plant": self.rejections.total, "plant_by_key": dict(self.rejections.by_key)},
            "contact": self.contact.summary(),
        }

