"""The link channel companion (issue 5): the only path from one agent's transmitter to another's receiver.

Thin I/O around the pure model of link/model.py. Subscribes to the clock, the truth (positions
at the time of sending), every agent's `isl/tx/<id>` and `sc/<id>/act`; delivers `IslPacket`s on
`isl/rx/<dst>`, publishes `LinkStats` on `link/stats` every `stats_period_s` of simulation time,
and, as a lockstep participant, a barrier `Tick` on `sync/channel` with header.step = k once step
k's deliveries are out.

Dating (issue 10). Every packet is dated by the step it was sent in, read from its own
header.step, never by the channel's clock: messages from the plant (tick, truth) and from the
agents (packets, commands) reach the channel over different paths, so a packet or a command of
step k may arrive before the channel has seen tick k (it is held until then), or, from a late
agent, after the window of step k has closed (it is evaluated against the truth of its own step,
kept for `LinkModel.truth_keep_steps`, and delivered at the next window; counted as late).

Step k's window closes when the truth of step k is in, every live agent's command of step k has
arrived, and with it every packet the command announces (`ActuatorCommand.isl_tx_count`: an
agent publishes its transmissions of step k before its command, but samples on different keys
need not arrive in that order, so the count, not the order, tells the channel it has them all). The plant publishes tick k and truth k before
the stimuli of step k, and waits for this barrier before step k+1: the receiver's `obs.isl_rx` at
step k+1 holds step k's deliveries, deterministically. In lockstep no window closes on wall
time, except (a) an agent declared dead (its liveliness token goes), (b) the plant moving on to
step k+1 without the barrier (its own stall timeout), or (c) the channel's stall timeout
(2 x `[supervision].stall_timeout_s`), which is reported as an `Event` of kind "link_stall".

Bad input (undecodable, foreign run, unknown or forged source, unknown destination, oversized
payload, a step outside the open window) is rejected, counted and recorded as an `Event` (kind
"rejected_packet"); the channel carries on.

Delivered packets carry header.source "channel", header.step = the receiver step that first sees
them, header.t = that step's time, and the sender's src, dst, type, payload and sent_t.
"""
from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from google.protobuf.message import DecodeError

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.base import Bus
from swarmhil.bus.codec import RejectedPacket, Rejections, arr, decode, header
from swarmhil.bus.keys import Keys
from swarmhil.bus.memory import MemoryBus
from swarmhil.link.faults import LinkFaults
from swarmhil.link.model import COUNTER_FIELDS, LinkConfig, LinkModel, check_tx, link_enabled, parse_link_config, reason_class

log = logging.getLogger("swarmhil.channel")

LOCKSTEP_BARRIER = True
NAME = "channel"
STALL_FACTOR = 2.0      # lockstep: a window open STALL_FACTOR x [supervision].stall_timeout_s after its tick is a stall
EARLY_STEPS = 1         # a packet or command may be dated at most this many steps after the channel's tick


def enabled(sc: Any, opts: dict[str, Any]) -> bool:
    """True when the scenario has a [link] table with enabled != false (validated here, so a bad
    table fails before any process starts)."""
    table = sc.sections.get("link")
    if table is None or not link_enabled(table):
        if table is not None and not isinstance(table, dict):
            parse_link_config(table, sc.source)
        return False
    parse_link_config(table, sc.source, sc.seed)
    return True


def start(bus: Bus, run: str, sc: Any, out: Path, opts: dict[str, Any]) -> "ChannelNode":
    cfg = parse_link_config(sc.sections["link"], sc.source, sc.seed)
    if sc.mode == "lockstep":
        # never on wall time in lockstep but for a real stall: the plant's own stall timeout (it
        # sees every process) moves the clock on first (a forced window then comes with tick k+1)
        watchdog_s, stall = STALL_FACTOR * sc.stall_timeout_s, True
    else:
        watchdog_s, stall = 0.7 * sc.step_s / sc.speed, False
    return ChannelNode(bus, run, cfg, sc.ids, sc.step_s, ref_radius_m=sc.orbit.semi_major_axis_m,
                       watchdog_s=None if isinstance(bus, MemoryBus) else watchdog_s, stall_is_error=stall,
                       faults=LinkFaults(getattr(sc, "faults", None) or [], sc.ids, sc.step_s))


class ChannelNode:
    def __init__(self, bus: Bus, run: str, cfg: LinkConfig, ids: list[str], step_s: float, *,
                 ref_radius_m: float = 6878137.0, watchdog_s: float | None = None,
                 stall_is_error: bool = False, faults: Any = None) -> None:
        self.bus = bus
        self.run = run
        self.keys = Keys(run)
        self.cfg = cfg
        self.ids = list(ids)
        self.known = set(self.ids)
        self.model = LinkModel(cfg, self.ids, step_s, faults)
        self.step_s = step_s
        self.ref_radius_m = ref_radius_m  # used when a truth message does not carry the reference orbit
        self.rejections = Rejections(NAME)
        self.rejected_by_reason: dict[str, int] = {}
        self.events_published = 0
        self._seq: dict[str, int] = {}
        self._lock = threading.RLock()
        self.step = -1                  # the plant's current step (last tick)
        self.t = 0.0
        self._expected: set[str] = set()
        self._acted: dict[str, int] = {}   # agent -> packets its command of this step announces
        self._window_done = True
        self._dead: set[str] = set()
        self._closed_upto = -1          # the newest step whose window has closed
        self._early_acts: dict[int, dict[str, int]] = {}  # commands that arrived before their tick
        self._tx_seen: dict[int, dict[str, int]] = {}     # step -> sender -> packets received on its key
        self._stall_is_error = stall_is_error
        self.early_packets = 0          # packets that reached the channel before their step's tick
        self.early_commands = 0
        self.late_packets = 0           # packets that reached it after their step's window closed
        self.stalls = 0
        self.waited_for_packets = 0     # windows whose last packet came after every command
        self._next_stats_t = 0.0
        self._stats_dirty = False
        self._finished = False
        self._started_config = False
        self.windows = 0
        self.forced_windows = 0
        self.deliveries = 0
        self.stats_published = 0
        self._tick_wall = 0.0
        self._subs = [
            bus.subscribe(self.keys.clock, self._on_tick),
            bus.subscribe(self.keys.truth, self._on_truth),
            bus.subscribe(self.keys.isl_tx_all, self._on_tx),
            bus.subscribe(self.keys.act_all, self._on_act),
            bus.watch_liveliness(self.keys.alive_all, self._on_liveliness),
        ]
        self._token = bus.declare_liveliness(self.keys.alive(NAME))
        self._stop = threading.Event()
        self._watchdog_s = watchdog_s
        if watchdog_s:
            threading.Thread(target=self._watchdog, name="channel-watchdog", daemon=True).start()

    # --- helpers --------------------------------------------------------------------------------
    def _hdr(self, key: str, step: int, t: float) -> pb.Header:
        seq = self._seq.get(key, 0)
        self._seq[key] = seq + 1
        return header(self.run, NAME, step, t, seq)

    def _event(self, kind: str, subject: str, detail: str) -> None:
        ev = pb.Event(header=self._hdr(self.keys.event, max(self.step, 0), self.t), kind=kind, subject=subject, detail=detail)
        self.bus.publish(self.keys.event, ev.SerializeToString())
        self.events_published += 1

    def _reject(self, key: str, subject: str, reason: str) -> None:
        self.rejections.add(key, reason)
        cls = reason_class(reason)
        self.rejected_by_reason[cls] = self.rejected_by_reason.get(cls, 0) + 1
        if self.rejections.total <= self.cfg.max_events:
            self._event("rejected_packet", subject, f"{key}: {reason}")

    # --- callbacks (one dispatcher thread) ---------------------------------------------------------
    def _on_tick(self, key: str, payload: bytes) -> None:
        try:
            tick = decode(pb.Tick, payload, run=self.run)
            if tick.header.source != "plant":
                raise RejectedPacket(f"clock tick from {tick.header.source!r}, not from the plant")
        except RejectedPacket as exc:
            log.warning("clock sample rejected: %s", exc)
            return
        with self._lock:
            if self._finished:
                return
            k = int(tick.header.step)
            if k <= self.step and not tick.final:
                return  # a repeated or stale tick
            if not self._window_done and k > self.step:
                self.forced_windows += 1
                self._close_window()  # real time, or an agent that never acted: the tick moved on
            if not self._started_config:
                self._started_config = True
                self._event("link_config", NAME, json.dumps({**self.cfg.to_dict(), "ids": self.ids, "step_s": self.step_s}))
            self.step, self.t = k, tick.header.t
            if tick.final:
                self._finish(k)
                return
            self._expected = (set(tick.alive) & self.known) - self._dead
            self._acted = self._early_acts.pop(k, {})
            for old in [s for s in self._early_acts if s < k]:
                del self._early_acts[old]
            for old in [s for s in self._tx_seen if s < k - 1]:
                del self._tx_seen[old]
            self._window_done = False
            self._tick_wall = time.monotonic()
            self._maybe_close()

    def _on_truth(self, key: str, payload: bytes) -> None:
        try:
            truth = decode(pb.Truth, payload, run=self.run)
            if truth.header.source != "plant":
                raise RejectedPacket(f"truth from {truth.header.source!r}, not from the plant")
        except RejectedPacket as exc:
            log.warning("truth sample rejected: %s", exc)
            return
        pos = np.full((len(self.ids), 3), np.nan)
        for b in truth.bodies:
            j = self.model.index.get(b.id)
            if j is not None:
                pos[j] = arr(b.position_m)
        with self._lock:
            a_m = truth.semi_major_axis_m if truth.semi_major_axis_m > 0 else self.ref_radius_m
            self.model.set_truth(int(truth.header.step), pos, a_m)
            self._maybe_close()

    def _on_tx(self, key: str, payload: bytes) -> None:
        try:
            _kind, key_id, _ = self.keys.parse(key)
        except ValueError:
            key_id = None
        subject = key_id or key
        try:
            pkt = decode(pb.IslPacket, payload, run=self.run)
        except RejectedPacket as exc:
            with self._lock:
                self._reject(key, subject, f"malformed: {exc}")
            return
        reason = check_tx(key_id, pkt.src, pkt.dst, len(pkt.payload), self.known, self.cfg.max_payload_bytes)
        with self._lock:
            if key_id in self.known:  # what the sender's command will announce: arrivals on its key
                seen = self._tx_seen.setdefault(int(pkt.header.step), {})
                seen[key_id] = seen.get(key_id, 0) + 1
            if reason:
                self._reject(key, subject, reason)
            else:
                self._accept_tx(key, subject, pkt)
            self._tx_arrived()

    def _accept_tx(self, key: str, subject: str, pkt: pb.IslPacket) -> None:
        """Date a valid packet by its own header.step and hand it to the model (lock held)."""
        step = int(pkt.header.step)
        newest = max(self.step, 0) + EARLY_STEPS
        if step > newest:
            self._reject(key, subject, f"bad step: packet dated step {step}, the channel is at step {self.step} "
                                       f"(accepts up to {newest})")
            return
        if step <= self._closed_upto:
            if not self.model.has_truth(step):
                self._reject(key, subject, f"late packet: step {step} is older than the truth kept "
                                           f"({self.model.truth_keep_steps} steps)")
                return
            self.late_packets += 1
            log.warning("late packet from %s dated step %d (window closed up to %d): delivered at the next window",
                        pkt.src, step, self._closed_upto)
        elif step > self.step:
            self.early_packets += 1
        self.model.submit(pkt.src, pkt.dst, pkt.type, pkt.payload, pkt.header.seq, step, step * self.step_s)

    def _on_act(self, key: str, payload: bytes) -> None:
        try:
            _kind, sc, _ = self.keys.parse(key)
            cmd = pb.ActuatorCommand.FromString(payload)  # only its header matters here
        except (DecodeError, ValueError, RuntimeWarning):
            return  # the plant validates and counts bad commands
        if sc is None or cmd.header.source != sc or cmd.header.run != self.run:
            return
        k = int(cmd.header.step)
        with self._lock:
            if k == self.step and not self._window_done:
                self._acted[sc] = int(cmd.isl_tx_count)
                self._maybe_close()
            elif self.step < k <= max(self.step, 0) + EARLY_STEPS:
                self._early_acts.setdefault(k, {})[sc] = int(cmd.isl_tx_count)  # before its tick: held
                self.early_commands += 1

    def _on_liveliness(self, key: str, alive: bool) -> None:
        proc = key.rsplit("/", 1)[-1]
        if not proc.startswith("agent-"):
            return
        sc = proc[len("agent-"):]
        with self._lock:
            if alive:
                self._dead.discard(sc)
            else:
                self._dead.add(sc)
                self._expected.discard(sc)
                self._maybe_close()

    # --- windows ----------------------------------------------------------------------------------
    def _missing(self) -> list[str]:
        """Live agents whose command, or one of the packets it announces, has not arrived yet."""
        seen = self._tx_seen.get(self.step, {})
        return sorted(s for s in self._expected if s not in self._acted or seen.get(s, 0) < self._acted[s])

    def _complete(self) -> bool:
        """`not self._missing()` without building the sorted list: called on every command and
        packet (issue 29: with 20 agents the list cost 1.5 % of a paper 000 run)."""
        acted = self._acted
        if not self._expected <= acted.keys():
            return False
        seen = self._tx_seen.get(self.step, {})
        return all(seen.get(s, 0) >= acted[s] for s in self._expected if acted[s])

    def _maybe_close(self) -> None:
        if (not self._window_done and self.step >= 0 and self.model.has_truth(self.step)
                and self._complete()):
            self._close_window()

    def _tx_arrived(self) -> None:
        """A packet came in: it may be the last one a command announced."""
        if not self._window_done and self.step >= 0 and self._expected <= set(self._acted):
            before = self._window_done
            self._maybe_close()
            if self._window_done and not before:
                self.waited_for_packets += 1

    def _close_window(self) -> None:
        k = self.step
        self._window_done = True
        self._closed_upto = max(self._closed_upto, k)
        self.windows += 1
        self._publish(self.model.window(k))
        if self.t + 1e-9 >= self._next_stats_t:
            self._publish_stats(k, self.t)
            while self._next_stats_t <= self.t + 1e-9:
                self._next_stats_t += self.cfg.stats_period_s
        sync = pb.Tick(header=self._hdr(self.keys.sync(NAME), k, self.t), step_s=self.step_s)
        self.bus.publish(self.keys.sync(NAME), sync.SerializeToString())

    def _force_window(self, step: int) -> None:
        with self._lock:
            if step == self.step and not self._window_done and not self._finished:
                self.forced_windows += 1
                missing = self._missing()
                truth = "in" if self.model.has_truth(step) else "missing"
                detail = (f"step {step}: window open {self._watchdog_s:.0f} s after its tick; no command yet from "
                          f"{missing[:5]}, truth {truth}; closing it")
                if self._stall_is_error:
                    self.stalls += 1
                    log.error("link stall: %s", detail)
                    self._event("link_stall", NAME, detail)
                else:
                    log.warning("%s", detail)
                self._close_window()

    def _watchdog(self) -> None:
        while not self._stop.wait(0.05):
            with self._lock:
                due = (not self._window_done and not self._finished and self.step >= 0 and self._watchdog_s is not None
                       and time.monotonic() - self._tick_wall > self._watchdog_s)
                step = self.step
            if due:
                call_soon = getattr(self.bus, "call_soon", None)
                if call_soon:
                    call_soon(self._force_window, step)
                    self._tick_wall = time.monotonic()  # one nudge per watchdog period

    def _publish(self, deliveries: list) -> None:
        for d in deliveries:
            key = self.keys.isl_rx(d.dst)
            pkt = pb.IslPacket(header=self._hdr(key, d.rx_step, d.rx_step * self.step_s), src=d.src, dst=d.packet_dst,
                               type=d.type, payload=d.payload, sent_t=d.send_t)
            self.bus.publish(key, pkt.SerializeToString())
        self.deliveries += len(deliveries)
        if deliveries:
            self._stats_dirty = True

    def _publish_stats(self, step: int, t: float) -> None:
        tot = self.model.counters.totals()
        st = pb.LinkStats(header=self._hdr(self.keys.link_stats, step, t), links=self.model.counters.to_pb(),
                          rejected_packets=self.rejections.total, tx_messages=tot["tx_messages"],
                          rx_messages=tot["rx_messages"])
        self.bus.publish(self.keys.link_stats, st.SerializeToString())
        self.stats_published += 1
        self._stats_dirty = False
        self._last_stats = (tot, self.rejections.total)

    def _finish(self, final_step: int) -> None:
        self._finished = True
        self._window_done = True
        self._publish(self.model.finish(final_step))
        self._publish_stats(final_step, self.t)

    # --- end --------------------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        tot = self.model.counters.totals()
        return {
            "config": self.cfg.to_dict(),
            "totals": {**tot, "rejected_packets": self.rejections.total},
            "rejected_by_reason": dict(sorted(self.rejected_by_reason.items())),
            "pending_at_end": self.model.pending(),
            "windows": self.windows,
            "forced_windows": self.forced_windows,
            "stalls": self.stalls,
            "early_packets": self.early_packets,
            "early_commands": self.early_commands,
            "late_packets": self.late_packets,
            "waited_for_packets": self.waited_for_packets,
            "max_truth_lag_steps": self.model.max_truth_lag_steps,
            "stats_published": self.stats_published,
            "events_published": self.events_published,
            "link_columns": ["src", "dst", "type", *COUNTER_FIELDS],
            "links": [[s, d, t, *r] for s, d, t, r in self.model.counters.sorted_rows()],
        }

    def close(self) -> dict[str, Any]:
        self._stop.set()
        for h in self._subs:
            try:
                h.undeclare()
            except Exception:
                pass
        flush = getattr(self.bus, "flush", None)
        if flush:
            flush()
        with self._lock:
            last = getattr(self, "_last_stats", None)
            if last != (self.model.counters.totals(), self.rejections.total):
                self._publish_stats(max(self.step, 0), self.t)  # the recording's last LinkStats = these totals
            s = self.summary()
        try:
            self._token.undeclare()
        except Exception:
            pass
        return s
