"""Inter-satellite link model (issue 5): pure functions and small classes, no I/O.

What a packet goes through, in this order (link/node.py does the I/O around it):

1. validation (`check_tx`): the key's id is a known spacecraft and equals the packet's `src`, the
   destination is empty (broadcast) or another known spacecraft, the payload fits;
2. the transmitter's radio (`Radio`): a FIFO served at `bitrate_bps` (fluid model: a packet of
   W wire bytes occupies the radio for 8 W / bitrate seconds), with at most `queue_packets`
   packets waiting; on overflow the newest (`drop_policy = "tail"`) or the oldest waiting
   (`"head"`) packet is dropped;
3. per addressed receiver, from the plant's truth at the time of sending: range gating
   (`distance <= range_m`, seed 000 section 2.2: communication range R_c), Earth occultation
   (`line_of_sight_clear`), then the link faults of the scenario's `[[fault]]` (link/faults.py:
   a partition drops, a degraded link adds loss and latency), then a seeded loss draw (`loss_draw`);
4. delivery at the first receiver step whose time is >= end of transmission + `latency_s`
   (never the sending step itself: the receiver has already acted on it).

Every outcome is counted per link (source, destination) and message type (`Counters`).
Positions are LVLH (x radial, y along-track, z cross-track) of the reference orbit.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass, field
from operator import attrgetter
from typing import Any, Iterable, Sequence

import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.plant.dynamics.constants import R_EARTH_M  # the one definition of the shared constants

FAULT_LOSS_SALT = 0xFA171055  # a degraded link's extra loss is drawn apart from the link's own (link/faults.py)

TX_ROW = "*"  # LinkCounter.dst of a transmitter's own row (what it offered to its radio, queue drops)
COUNTER_FIELDS = ("messages", "payload_bytes", "wire_bytes", "dropped_range", "dropped_occulted",
                  "dropped_lost", "dropped_queue", "dropped_fault")
DROP_CAUSES = ("range", "occulted", "lost", "queue", "fault")
_MSG, _PAY, _WIRE, _RANGE, _OCC, _LOST, _QUEUE, _FAULT = range(8)


class LinkConfigError(ValueError):
    """A bad [link] table; the message names the file and the field."""


@dataclass(frozen=True)
class LinkConfig:
    """The scenario's [link] table, validated (units in the names)."""

    range_m: float = 1000.0
    loss_probability: float = 0.0
    latency_s: float = 0.0
    bitrate_bps: float = 0.0          # 0: no cap
    queue_packets: int = 16           # packets waiting per transmitter (the one on air not counted)
    drop_policy: str = "tail"         # "tail": drop the newcomer; "head": drop the oldest waiting
    overhead_bytes: int = 0           # framing a real radio adds to every packet
    max_payload_bytes: int = 4096
    occultation: bool = True
    earth_radius_m: float = R_EARTH_M
    grazing_altitude_m: float = 0.0   # line of sight must clear the Earth by this much
    stats_period_s: float = 60.0      # LinkStats period in simulation time
    seed: int = 0
    max_events: int = 1000            # rejected-packet Events recorded at most (all are counted)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


_FIELDS = set(LinkConfig.__dataclass_fields__) | {"enabled"}


def _bad(src: str, name: str, msg: str, got: Any) -> LinkConfigError:
    return LinkConfigError(f"{src}: [link].{name} {msg} (got {got!r})")


def _number(src: str, t: dict[str, Any], name: str, default: float, lo: float, hi: float = math.inf,
            lo_open: bool = False) -> float:
    v = t.get(name, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _bad(src, name, "must be a finite number", v)
    if v < lo or (lo_open and v == lo) or v > hi:
        bound = f"{'>' if lo_open else '>='} {lo:g}" if hi == math.inf else f"in [{lo:g}, {hi:g}]"
        raise _bad(src, name, f"must be {bound}", v)
    return float(v)


def _integer(src: str, t: dict[str, Any], name: str, default: int, lo: int) -> int:
    v = t.get(name, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < lo:
        raise _bad(src, name, f"must be an integer >= {lo}", v)
    return int(v)


def _flag(src: str, t: dict[str, Any], name: str, default: bool) -> bool:
    v = t.get(name, default)
    if not isinstance(v, bool):
        raise _bad(src, name, "must be true or false", v)
    return v


def link_enabled(table: Any) -> bool:
    return isinstance(table, dict) and table.get("enabled", True) is not False


def parse_link_config(table: Any, src: str = "<scenario>", default_seed: int = 0) -> LinkConfig:
    """Validate a raw [link] table; errors name the file and the field."""
    if not isinstance(table, dict):
        raise LinkConfigError(f"{src}: [link] must be a table (got {table!r})")
    unknown = sorted(set(table) - _FIELDS)
    if unknown:
        raise _bad(src, unknown[0], f"is not a known field; known: {sorted(_FIELDS)}", table[unknown[0]])
    _flag(src, table, "enabled", True)
    policy = table.get("drop_policy", "tail")
    if policy not in ("tail", "head"):
        raise _bad(src, "drop_policy", "must be one of ['tail', 'head']", policy)
    return LinkConfig(
        range_m=_number(src, table, "range_m", 1000.0, 0.0, lo_open=True),
        loss_probability=_number(src, table, "loss_probability", 0.0, 0.0, 1.0),
        latency_s=_number(src, table, "latency_s", 0.0, 0.0),
        bitrate_bps=_number(src, table, "bitrate_bps", 0.0, 0.0),
        queue_packets=_integer(src, table, "queue_packets", 16, 0),
        drop_policy=policy,
        overhead_bytes=_integer(src, table, "overhead_bytes", 0, 0),
        max_payload_bytes=_integer(src, table, "max_payload_bytes", 4096, 1),
        occultation=_flag(src, table, "occultation", True),
        earth_radius_m=_number(src, table, "earth_radius_m", R_EARTH_M, 0.0, lo_open=True),
        grazing_altitude_m=_number(src, table, "grazing_altitude_m", 0.0, 0.0),
        stats_period_s=_number(src, table, "stats_period_s", 60.0, 0.0, lo_open=True),
        seed=_integer(src, table, "seed", default_seed, 0),
        max_events=_integer(src, table, "max_events", 1000, 0),
    )


# --- geometry -------------------------------------------------------------------------------------
def ranges_from_m(positions_m: np.ndarray, i: int) -> np.ndarray:
    """Euclidean distance from body i to every body, (N,) metres."""
    return np.linalg.norm(positions_m - positions_m[i], axis=1)


def in_range(distance_m: float | np.ndarray, range_m: float) -> bool | np.ndarray:
    """Seed 000 section 2.2: neighbours share information only inside the communication range R_c (inclusive)."""
    return distance_m <= range_m


def line_of_sight_clear(p1_m: np.ndarray, p2_m: np.ndarray, ref_radius_m: float,
                        earth_radius_m: float = R_EARTH_M) -> bool | np.ndarray:
    """True when the segment p1-p2 (LVLH, metres) does not pass through the Earth sphere.

    In the LVLH frame of a reference orbit of radius a the Earth's centre is at (-a, 0, 0). The
    segment is blocked when its closest point to the centre is within earth_radius_m: closest point
    p1 + s (p2 - p1), s = clip(((c - p1) . d) / (d . d), 0, 1) (point-segment distance). Broadcasts
    over rows: p1_m, p2_m of shape (3,) or (N, 3).
    """
    p1 = np.asarray(p1_m, dtype=float)
    p2 = np.asarray(p2_m, dtype=float)
    c = np.array([-float(ref_radius_m), 0.0, 0.0])
    d = p2 - p1
    f = c - p1
    # np.sum, np.clip and np.linalg.norm's arithmetic without their Python (issue 29: per packet)
    dd = np.add.reduce(d * d, axis=-1)
    s = (np.add.reduce(f * d, axis=-1) / np.where(dd > 0.0, dd, 1.0)).clip(0.0, 1.0)
    closest = p1 + s[..., None] * d
    e = c - closest
    dist = np.sqrt(np.add.reduce(e * e, axis=-1))
    clear = dist > earth_radius_m
    return bool(clear) if np.ndim(clear) == 0 else clear


def _above_the_limb(positions_m: np.ndarray, ref_radius_m: float, blocking_radius_m: float) -> bool:
    """True when no segment between two of the (finite) positions can come near the Earth, so that
    `line_of_sight_clear` is True for every pair: every point of such a segment lies in the ball of
    radius R = max |p| about the LVLH origin (a ball is convex), at least a - R from the Earth's
    centre (-a, 0, 0) (triangle inequality); a - R beyond the blocking radius by a metre and a
    millionth of a (far more than the rounding of the test's arithmetic) leaves every verdict clear.
    NaN rows are left out (out of range, never tested); a NaN-only truth is not above the limb."""
    r2 = np.fmax.reduce(np.add.reduce(positions_m * positions_m, axis=1)) if len(positions_m) else np.nan
    return bool(ref_radius_m - math.sqrt(r2) > blocking_radius_m + 1.0 + 1e-6 * ref_radius_m) if r2 == r2 else False


# --- seeded loss ----------------------------------------------------------------------------------
_MASK64 = (1 << 64) - 1


def _splitmix64(x: int) -> int:
    """SplitMix64 finaliser (Steele, Lea, Flood 2014): a bijective 64-bit mixer."""
    x = (x + 0x9E3779B97F4A7C15) & _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def loss_draw(seed: int, src_index: int, tx_index: int, dst_index: int) -> float:
    """Uniform [0, 1) for one (transmission, receiver): counter-based, so independent of the order
    in which the channel happens to evaluate packets (the same seed gives the same losses)."""
    x = _splitmix64(seed & _MASK64)
    for v in (src_index, tx_index, dst_index):
        x = _splitmix64(x ^ (v & _MASK64))
    return (x >> 11) * (1.0 / (1 << 53))


# --- validation -----------------------------------------------------------------------------------
def check_tx(key_id: str | None, src: str, dst: str, payload_len: int, ids: Iterable[str],
             max_payload_bytes: int) -> str | None:
    """Reason to reject a decoded IslPacket sent on isl/tx/<key_id>, or None when it is acceptable."""
    known = ids if isinstance(ids, (set, frozenset, dict)) else set(ids)
    if key_id not in known:
        return f"unknown source: key id {key_id!r}"
    if src != key_id:
        return f"forged source: packet src {src!r} sent on the key of {key_id!r}"
    if dst and dst not in known:
        return f"unknown destination: {dst!r}"
    if dst == src:
        return f"destination is the source: {dst!r}"
    if payload_len > max_payload_bytes:
        return f"oversized payload: {payload_len} B > {max_payload_bytes} B"
    return None


def reason_class(reason: str) -> str:
    """The class of a rejection reason ("forged source", "oversized payload", "malformed", ...)."""
    return reason.split(":", 1)[0]


# --- the radio of one transmitter -----------------------------------------------------------------
@dataclass
class TxPacket:
    src: str
    dst: str                 # "" for broadcast
    type: str
    payload: bytes
    send_step: int
    send_t: float
    seq: int                 # the sender's header.seq (tie-break only)
    arrival: int             # order of arrival at the channel (last tie-break)
    wire_bytes: int = 0
    tx_index: int = -1       # per-transmitter index assigned by the channel in deterministic order
    t_start: float = math.nan
    t_done: float = math.nan


class Radio:
    """One transmitter: FIFO served at bitrate_bps, at most queue_packets waiting.

    A packet starts when the radio is free (free_t <= now); packets arriving at the same instant
    as the radio frees queue behind the head. Busy intervals never overlap, so the bits finished in
    any interval [t0, t1] are at most bitrate * (t1 - t0) plus one packet.
    """

    def __init__(self, bitrate_bps: float, queue_packets: int, drop_policy: str) -> None:
        self.bitrate_bps = float(bitrate_bps)
        self.queue_packets = int(queue_packets)
        self.drop_policy = drop_policy
        self.free_t = -math.inf
        self.queue: deque[TxPacket] = deque()

    def duration_s(self, pkt: TxPacket) -> float:
        return 0.0 if self.bitrate_bps <= 0 else pkt.wire_bytes * 8.0 / self.bitrate_bps

    def advance(self, t: float) -> list[TxPacket]:
        """Start every queued packet the radio gets to by time t; returns them (t_start, t_done set)."""
        started = []
        while self.queue and self.free_t <= t:
            p = self.queue.popleft()
            p.t_start = max(self.free_t, p.send_t)
            p.t_done = p.t_start + self.duration_s(p)
            self.free_t = p.t_done
            started.append(p)
        return started

    def offer(self, pkt: TxPacket) -> tuple[list[TxPacket], list[TxPacket]]:
        """Queue one packet at its send time: (started, dropped)."""
        started = self.advance(pkt.send_t)
        self.queue.append(pkt)
        started += self.advance(pkt.send_t)
        dropped = []
        if self.bitrate_bps > 0 and len(self.queue) > self.queue_packets:
            dropped.append(self.queue.pop() if self.drop_policy == "tail" else self.queue.popleft())
        return started, dropped


# --- accounting -----------------------------------------------------------------------------------
class Counters:
    """Cumulative counters per (src, dst, type); dst = TX_ROW for the transmitter's own row."""

    def __init__(self) -> None:
        self.rows: dict[tuple[str, str, str], list[int]] = {}

    def _row(self, src: str, dst: str, typ: str) -> list[int]:
        """The counters of (src, dst, typ), in the order of COUNTER_FIELDS (made at the first use)."""
        r = self.rows.get((src, dst, typ))
        if r is None:
            r = self.rows[(src, dst, typ)] = [0] * len(COUNTER_FIELDS)
        return r

    def add_tx(self, src: str, typ: str, payload_bytes: int, wire_bytes: int) -> None:
        r = self._row(src, TX_ROW, typ)
        r[_MSG] += 1
        r[_PAY] += payload_bytes
        r[_WIRE] += wire_bytes

    def add_rx(self, src: str, dst: str, typ: str, payload_bytes: int, wire_bytes: int) -> None:
        r = self._row(src, dst, typ)
        r[_MSG] += 1
        r[_PAY] += payload_bytes
        r[_WIRE] += wire_bytes

    def add_drop(self, src: str, dst: str, typ: str, cause: str) -> None:
        self._row(src, dst, typ)[_RANGE + DROP_CAUSES.index(cause)] += 1

    def totals(self) -> dict[str, int]:
        tx = np.zeros(len(COUNTER_FIELDS), dtype=np.int64)
        rx = np.zeros(len(COUNTER_FIELDS), dtype=np.int64)
        for (_s, d, _t), r in self.rows.items():
            (tx if d == TX_ROW else rx)[:] += r
        return {
            "tx_messages": int(tx[_MSG]), "tx_payload_bytes": int(tx[_PAY]), "tx_wire_bytes": int(tx[_WIRE]),
            "rx_messages": int(rx[_MSG]), "rx_payload_bytes": int(rx[_PAY]), "rx_wire_bytes": int(rx[_WIRE]),
            "dropped_range": int(rx[_RANGE]), "dropped_occulted": int(rx[_OCC]), "dropped_lost": int(rx[_LOST]),
            "dropped_queue": int(tx[_QUEUE]), "dropped_fault": int(rx[_FAULT]),
        }

    def sorted_rows(self) -> list[tuple[str, str, str, list[int]]]:
        return [(s, d, t, list(r)) for (s, d, t), r in sorted(self.rows.items())]

    def to_pb(self) -> list[pb.LinkCounter]:
        return [pb.LinkCounter(src=s, dst=d, type=t, **dict(zip(COUNTER_FIELDS, r))) for s, d, t, r in self.sorted_rows()]


# --- the model ------------------------------------------------------------------------------------
@dataclass(order=True)
class Delivery:
    """One packet for one receiver, delivered at the receiver's step `rx_step`."""

    sort_key: tuple = field(repr=False)
    src: str = field(compare=False)
    dst: str = field(compare=False)          # the receiver
    packet_dst: str = field(compare=False)   # what the sender addressed ("" broadcast)
    type: str = field(compare=False)
    payload: bytes = field(compare=False)
    send_step: int = field(compare=False)
    send_t: float = field(compare=False)
    arrive_t: float = field(compare=False)
    due_step: int = field(compare=False)
    rx_step: int = field(compare=False, default=-1)
    wire_bytes: int = field(compare=False, default=0)


_sort_key = attrgetter("sort_key")


class LinkModel:
    """State of the link for one run: radios, packets in flight, truth by step, counters.

    Deterministic: a window processes the packets it holds sorted by (send step, source, sender
    seq, arrival), loss draws are counter-based, and deliveries come out sorted by
    (send step, source, tx index, receiver).
    """

    def __init__(self, cfg: LinkConfig, ids: Sequence[str], step_s: float, faults: Any = None) -> None:
        self.cfg = cfg
        self.faults = faults if faults else None  # link/faults.py LinkFaults (issue 27)
        self.ids = list(ids)
        self.index = {s: i for i, s in enumerate(self.ids)}
        self.step_s = float(step_s)
        self.radios = {s: Radio(cfg.bitrate_bps, cfg.queue_packets, cfg.drop_policy) for s in self.ids}
        self.counters = Counters()
        self._submitted: list[TxPacket] = []
        self._arrivals = 0
        self._tx_index = {s: 0 for s in self.ids}
        self._on_air: list[TxPacket] = []           # started, receivers not evaluated yet (truth missing)
        self._scheduled: list[Delivery] = []        # evaluated, waiting for their receiver step
        self._truth: dict[int, tuple[np.ndarray, float]] = {}
        self._geom: dict[int, tuple[list[list[bool]], list[list[bool]]]] = {}  # step -> `_geometry`
        self._receivers_of: dict[tuple[str, str], list[tuple[str, int]]] = {}
        self.max_truth_lag_steps = 0
        self.truth_keep_steps = 64  # truth kept behind the newest step, for packets that arrive late

    def has_truth(self, step: int) -> bool:
        return int(step) in self._truth

    # inputs
    def submit(self, src: str, dst: str, typ: str, payload: bytes, seq: int, send_step: int, send_t: float) -> None:
        self._submitted.append(TxPacket(src, dst, typ, bytes(payload), int(send_step), float(send_t), int(seq),
                                        self._arrivals, len(payload) + self.cfg.overhead_bytes))
        self._arrivals += 1

    def set_truth(self, step: int, positions_m: np.ndarray, ref_radius_m: float) -> None:
        """Positions (N,3) in the order of `ids` at step `step` (NaN rows: body not in the truth)."""
        self._truth[int(step)] = (np.asarray(positions_m, dtype=float), float(ref_radius_m))
        self._geom.pop(int(step), None)

    # processing
    def _time(self, step: int) -> float:
        return step * self.step_s

    def _offer_submitted(self, upto_step: int) -> list[TxPacket]:
        """Offer to the radios the packets sent at steps <= upto_step; packets dated later (they
        reached the channel before their step's window) stay held."""
        ready = [p for p in self._submitted if p.send_step <= upto_step]
        self._submitted = [p for p in self._submitted if p.send_step > upto_step]
        batch = sorted(ready, key=lambda p: (p.send_step, self.index[p.src], p.seq, p.arrival))
        started: list[TxPacket] = []
        for p in batch:
            p.tx_index = self._tx_index[p.src]
            self._tx_index[p.src] += 1
            self.counters.add_tx(p.src, p.type, len(p.payload), p.wire_bytes)
            s, dropped = self.radios[p.src].offer(p)
            started += s
            for d in dropped:
                self.counters.add_drop(d.src, TX_ROW, d.type, "queue")
        return started

    def _geometry(self, step: int) -> tuple[list[list[bool]], list[list[bool]]]:
        """Range gate and line of sight of every (source, receiver) pair at `step`, made once a
        step for all the packets sent at it: rows by source, columns by receiver. Each pair's
        numbers are the per-packet test's (pos[j] - pos[i], its norm as the sum of squares along the
        last axis, `line_of_sight_clear` from pos[i] to pos[j]): elementwise, so the same bits."""
        got = self._geom.get(step)
        if got is not None:
            return got
        cfg = self.cfg
        pos, ref_radius_m = self._truth[step]
        rel = pos[None, :, :] - pos[:, None, :]            # rel[i, j] = pos[j] - pos[i]
        dist = np.sqrt(np.add.reduce(rel * rel, axis=2))  # np.linalg.norm's arithmetic
        reach = dist <= cfg.range_m  # NaN (body missing from the truth) counts as out of range
        if cfg.occultation and reach.any() and not _above_the_limb(pos, ref_radius_m, cfg.earth_radius_m + cfg.grazing_altitude_m):
            clear = np.asarray(line_of_sight_clear(np.broadcast_to(pos[:, None, :], rel.shape),
                                                   np.broadcast_to(pos[None, :, :], rel.shape), ref_radius_m,
                                                   cfg.earth_radius_m + cfg.grazing_altitude_m))
        else:
            clear = np.ones(reach.shape, dtype=bool)
        got = self._geom[step] = (reach.tolist(), clear.tolist())
        return got

    def _receivers(self, src: str, dst: str) -> list[tuple[str, int]]:
        """The addressed receivers (id, index) of a packet from `src` to `dst` ("" broadcast: every other id)."""
        key = (src, dst)
        got = self._receivers_of.get(key)
        if got is None:
            got = self._receivers_of[key] = [(r, self.index[r]) for r in ([dst] if dst else [s for s in self.ids if s != src])]
        return got

    def _evaluate(self, p: TxPacket) -> None:
        """Range, occultation and loss for every addressed receiver, from the truth at the send step."""
        reach_all, clear_all = self._geometry(p.send_step)
        i = self.index[p.src]
        receivers = self._receivers(p.src, p.dst)
        reach, clear = reach_all[i], clear_all[i]
        arrive_t = p.t_done + self.cfg.latency_s
        due = max(p.send_step + 1, math.ceil(arrive_t / self.step_s - 1e-9))
        cfg = self.cfg
        fault = None if self.faults is None else self.faults.at(p.send_step, i, np.array([j for _r, j in receivers], dtype=int))
        for n, (r, j) in enumerate(receivers):
            at, due_j = arrive_t, due
            if not reach[j]:
                self.counters.add_drop(p.src, r, p.type, "range")
                continue
            elif not clear[j]:
                self.counters.add_drop(p.src, r, p.type, "occulted")
                continue
            if fault is not None:
                if fault.blocked[n] or (fault.loss_probability[n] > 0 and loss_draw(
                        cfg.seed ^ FAULT_LOSS_SALT, i, p.tx_index, j) < fault.loss_probability[n]):
                    self.counters.add_drop(p.src, r, p.type, "fault")
                    continue
                if fault.extra_latency_s[n] > 0:
                    at = arrive_t + float(fault.extra_latency_s[n])
                    due_j = max(p.send_step + 1, math.ceil(at / self.step_s - 1e-9))
            if cfg.loss_probability > 0 and loss_draw(cfg.seed, i, p.tx_index, j) < cfg.loss_probability:
                self.counters.add_drop(p.src, r, p.type, "lost")
            else:
                self._scheduled.append(Delivery((p.send_step, i, p.tx_index, j), p.src, r, p.dst, p.type, p.payload,
                                                p.send_step, p.send_t, at, due_j, wire_bytes=p.wire_bytes))

    def _progress(self, until_t: float, window_step: int) -> None:
        self._on_air += self._offer_submitted(window_step)
        for s in self.ids:
            self._on_air += self.radios[s].advance(until_t)
        waiting = []
        for p in self._on_air:
            if p.send_step in self._truth:
                self._evaluate(p)
            else:
                waiting.append(p)
        self._on_air = waiting
        if waiting:
            self.max_truth_lag_steps = max(self.max_truth_lag_steps, window_step - min(p.send_step for p in waiting) + 1)
        self._prune_truth()

    def _take(self, rx_step: int) -> list[Delivery]:
        out = [d for d in self._scheduled if d.due_step <= rx_step]
        self._scheduled = [d for d in self._scheduled if d.due_step > rx_step] if len(out) < len(self._scheduled) else []
        out.sort(key=_sort_key)  # Delivery's order (its sort_key alone), without its Python __lt__
        for d in out:
            d.rx_step = rx_step
            self.counters.add_rx(d.src, d.dst, d.type, len(d.payload), d.wire_bytes)
        return out

    def window(self, step: int) -> list[Delivery]:
        """Every live agent has acted at `step`: what its receivers must hold before step + 1."""
        self._progress(self._time(step + 1), step)
        return self._take(step + 1)

    def finish(self, final_step: int) -> list[Delivery]:
        """End of the run (final tick at `final_step`): deliver what has arrived by then."""
        self._progress(self._time(final_step), final_step)
        return self._take(final_step)

    def _prune_truth(self) -> None:
        keep_from = min([p.send_step for p in self._on_air] + [p.send_step for r in self.radios.values() for p in r.queue]
                        + [p.send_step for p in self._submitted]
                        + [max(self._truth, default=0) - self.truth_keep_steps])
        for k in [k for k in self._truth if k < keep_from]:
            del self._truth[k]
            self._geom.pop(k, None)

    def pending(self) -> dict[str, int]:
        """Packets not delivered (yet): waiting in a radio queue, on air without truth, scheduled."""
        return {"queued": sum(len(r.queue) for r in self.radios.values()) + len(self._submitted),
                "unevaluated": len(self._on_air), "scheduled_deliveries": len(self._scheduled)}
