"""Re-fly one spacecraft's flight software from a recording (issue 26): `swarmhil refly RUN --agent ID`.

A flight-software team's daily question is "did my change alter what the spacecraft would have
done?". A recording holds everything one agent received: its sensor stimuli
(`sc/<id>/sense/<kind>`) and its link deliveries (`isl/rx/<id>`), and everything it answered: its
commands (`sc/<id>/act`) and transmissions (`isl/tx/<id>`), with the run's scenario document (the
attachment `scenario.json`) and resolved configuration (metadata `swarmhil.config`; DESIGN, MCAP
contract). Re-flying builds that agent exactly as the launcher does (deploy/agent_image.py, from
today's code and the recorded document, with `--set` overrides on top), alone in this process on
the in-memory bus, feeds it the recorded inputs in the order lockstep gave them, and compares
every command and transmission it publishes with the recorded one, bit for bit.

The order lockstep gives (link/node.py): the link deliveries an agent holds when its stimulus of
step k arrives are exactly those the channel stamped with receiver step <= k (header.step of a
delivered packet is the receiver step that first sees it), in the channel's publication order,
which is the recording's order on that topic. So a lockstep recording re-flies bit for bit on the
machine that made it; a real-time recording re-flies what was delivered, but not when within a
step it arrived (docs/hil.md).
"""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import sense_type
from swarmhil.bus.keys import Keys
from swarmhil.bus.mcap_tools import relative_topic, run_of_recording, segment_name


class ReflyError(Exception):
    """A recording that cannot be re-flown for this agent: the message is one line for the user."""


class ReflyConfigError(ReflyError):
    """The agent cannot be built from the recorded scenario with these `--set` changes (usage error)."""


@dataclasses.dataclass
class Recorded:
    """What one agent received and answered in a recording, in lockstep order."""

    run: str
    sid: str
    document: dict[str, Any]                 # the scenario.json attachment: {"source", "sets", "doc"}
    config: dict[str, Any]                   # metadata swarmhil.config (the resolved configuration)
    sense_kind: str
    stimuli: list[tuple[int, bytes]]         # (step, payload), in step order
    rx: list[tuple[int, bytes]]              # (receiver step, payload), in the channel's order
    acts: dict[int, bytes]                   # step -> ActuatorCommand payload
    txs: dict[int, list[bytes]]              # step -> IslPacket payloads, in publication order


def segments(run: Path) -> list[Path]:
    """The recording of RUN: a run directory's run.mcap and its restart segments, or one .mcap file."""
    if run.is_file():
        return [run]
    out = []
    for i in range(1000):
        p = run / segment_name(i)
        if not p.is_file():
            break
        out.append(p)
    if not out:
        raise ReflyError(f"{run}: no recording here (run.mcap)")
    return out


WRAPPED = {pb.UndecodableSample.DESCRIPTOR.full_name, pb.RejectedSample.DESCRIPTOR.full_name}
"""The recorder's wrappers of samples no process acted on (bus/recorder.py): not inputs or outputs."""


def _iter_messages(paths: list[Path]) -> Iterator[tuple[str, bytes]]:
    """(topic, payload) of every recorded sample but the recorder's wrappers (WRAPPED)."""
    from mcap.reader import make_reader

    for p in paths:
        with open(p, "rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
                if schema is None or schema.name not in WRAPPED:
                    yield relative_topic(channel.topic), message.data


def _meta_and_document(path: Path) -> tuple[str | None, dict[str, Any] | None, dict[str, Any] | None]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        run = run_of_recording(reader)
        config = None
        for meta in reader.iter_metadata():
            if meta.name == "swarmhil.config":
                config = json.loads(meta.metadata["json"])
        document = None
        for att in reader.iter_attachments():
            if att.name == "scenario.json":
                document = json.loads(att.data)
    return run, config, document


def read_recorded(run_path: str | Path, sid: str) -> Recorded:
    """Agent `sid`'s inputs and outputs in the recording at `run_path` (a run directory or an .mcap)."""
    paths = segments(Path(run_path))
    run, config, document = _meta_and_document(paths[0])
    if config is None or document is None:
        raise ReflyError(f"{paths[0]}: the recording carries no scenario document or configuration "
                         "(metadata swarmhil.config, attachment scenario.json): it predates them")
    ids = [s["id"] for s in config.get("spacecraft", [])]
    if sid not in ids:
        raise ReflyError(f"{paths[0]}: no spacecraft {sid!r} in this run (it flew {', '.join(ids)})")
    kind = str(config.get("sensing", {}).get("kind"))
    stim_cls = sense_type(kind)
    stim_topic, rx_topic, act_topic, tx_topic = (f"sc/{sid}/sense/{kind}", f"isl/rx/{sid}", f"sc/{sid}/act",
                                                 f"isl/tx/{sid}")
    stimuli: dict[int, bytes] = {}
    rx: list[tuple[int, bytes]] = []
    acts: dict[int, bytes] = {}
    txs: dict[int, list[bytes]] = defaultdict(list)
    for topic, data in _iter_messages(paths):
        if topic == stim_topic:
            stimuli[int(stim_cls.FromString(data).header.step)] = data
        elif topic == rx_topic:
            rx.append((int(pb.IslPacket.FromString(data).header.step), data))
        elif topic == act_topic:
            acts[int(pb.ActuatorCommand.FromString(data).header.step)] = data
        elif topic == tx_topic:
            txs[int(pb.IslPacket.FromString(data).header.step)].append(data)
    if not stimuli:
        raise ReflyError(f"{paths[0]}: the recording holds no stimuli for {sid} (topic {stim_topic}); "
                         "refly needs a recording of every message (`swarmhil run` without --record truth)")
    return Recorded(run=run or str(config.get("run", {}).get("name")), sid=sid, document=document, config=config,
                    sense_kind=kind, stimuli=sorted(stimuli.items()), rx=rx, acts=acts, txs=dict(txs))


def agent_config_of(rec: Recorded, sets: tuple[str, ...] = ()) -> dict[str, Any]:
    """The agent's config as the launcher made it (deploy/agent_image.py), from the recorded scenario
    document and the run's seed, duration and mode, with `sets` (`--set SECTION.KEY=VALUE`) on top."""
    from swarmhil.deploy.agent_image import agent_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.scenario import load_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    run = rec.config.get("run", {})
    with tempfile.TemporaryDirectory(prefix="refly-") as d:
        p = Path(d) / "scenario.json"
        p.write_text(json.dumps(rec.document))
        sc = load_scenario(p, sets).with_overrides(duration_s=run.get("duration_s"), seed=run.get("seed"),
                                                   mode=run.get("mode"))
    return agent_config(sc, rec.sid)


@dataclasses.dataclass(frozen=True)
class FieldDiff:
    """One field of one step's output that differs: `recorded` against `now` (as text for non-numbers)."""

    step: int
    t_s: float
    field: str
    recorded: Any
    now: Any


def _vec(v: pb.Vector3) -> tuple[float, float, float]:
    return (v.x, v.y, v.z)


def _same(a: float, b: float) -> bool:
    """Bit for bit (NaN equal to itself: a recorded NaN re-flown as NaN is no divergence)."""
    return a == b or (math.isnan(a) and math.isnan(b))


def compare_step(step: int, t_s: float, recorded_act: bytes | None, now_act: bytes | None,
                 recorded_tx: list[bytes], now_tx: list[bytes]) -> list[FieldDiff]:
    """The fields of one step's command and transmissions that differ (empty: identical)."""
    diffs: list[FieldDiff] = []
    if recorded_act is None or now_act is None:
        if recorded_act is not now_act:
            diffs.append(FieldDiff(step, t_s, "command", "present" if recorded_act else "none",
                                   "present" if now_act else "none"))
        return diffs
    r, n = pb.ActuatorCommand.FromString(recorded_act), pb.ActuatorCommand.FromString(now_act)
    for name in ("accel_mps2", "torque_nm"):
        rv, nv = _vec(getattr(r, name)), _vec(getattr(n, name))
        if r.HasField(name) != n.HasField(name):
            diffs.append(FieldDiff(step, t_s, name, rv if r.HasField(name) else "unset",
                                   nv if n.HasField(name) else "unset"))
            continue
        for axis, a, b in zip("xyz", rv, nv):
            if not _same(a, b):
                diffs.append(FieldDiff(step, t_s, f"{name}.{axis}", a, b))
    for name in ("controller", "isl_tx_count"):
        if getattr(r, name) != getattr(n, name):
            diffs.append(FieldDiff(step, t_s, name, getattr(r, name), getattr(n, name)))
    if len(recorded_tx) != len(now_tx):
        diffs.append(FieldDiff(step, t_s, "transmissions", len(recorded_tx), len(now_tx)))
    for i, (a, b) in enumerate(zip(recorded_tx, now_tx)):
        pa, pb_ = pb.IslPacket.FromString(a), pb.IslPacket.FromString(b)
        for name in ("dst", "type", "payload"):
            if getattr(pa, name) != getattr(pb_, name):
                shown = (lambda v: f"{len(v)} B" if isinstance(v, bytes) else v)
                diffs.append(FieldDiff(step, t_s, f"transmission[{i}].{name}", shown(getattr(pa, name)),
                                       shown(getattr(pb_, name))))
    return diffs


@dataclasses.dataclass
class ReflyResult:
    sid: str
    steps: int                                   # steps re-flown
    diffs: list[FieldDiff]                       # every differing field of every step
    accel_delta: list[tuple[int, float, float, float, float, float, float, float]]  # step, t, recorded xyz, now xyz
    wall_s: float

    @property
    def first(self) -> FieldDiff | None:
        return self.diffs[0] if self.diffs else None

    def verdict(self) -> str:
        """One line: the first divergence (step, time, field, recorded vs now), or identical over N steps."""
        d = self.first
        if d is None:
            return f"{self.sid}: identical over {self.steps} steps (commands and transmissions, bit for bit)"
        return (f"{self.sid}: first divergence at step {d.step} (t = {d.t_s:g} s): {d.field} recorded {d.recorded!r}, "
                f"now {d.now!r} ({len({x.step for x in self.diffs})} of {self.steps} steps differ)")


def refly(rec: Recorded, cfg: dict[str, Any], until_s: float | None = None) -> ReflyResult:
    """Fly agent `rec.sid` alone on the in-memory bus over its recorded inputs; compare its outputs."""
    from swarmhil.bus.memory import MemoryBus  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.deploy.agent_image import build_agent  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    keys = Keys(rec.run)
    bus = MemoryBus()
    acts: dict[int, bytes] = {}
    txs: dict[int, list[bytes]] = defaultdict(list)
    bus.subscribe(keys.act(rec.sid), lambda _k, p: acts.__setitem__(pb.ActuatorCommand.FromString(p).header.step, p))
    bus.subscribe(keys.isl_tx(rec.sid), lambda _k, p: txs[pb.IslPacket.FromString(p).header.step].append(p))
    try:
        node = build_agent(bus, rec.run, cfg)
    except (ValueError, TypeError, KeyError) as exc:  # the controller's own parameter check (e.g. --set of an unknown gain)
        raise ReflyConfigError(f"{rec.sid}: cannot build its flight software: {exc}") from None
    stim_key, rx_key = keys.sense(rec.sid, rec.sense_kind), keys.isl_rx(rec.sid)
    stim_cls = sense_type(rec.sense_kind)
    diffs: list[FieldDiff] = []
    accel: list[tuple[int, float, float, float, float, float, float, float]] = []
    i_rx, n = 0, 0
    t0 = time.perf_counter()
    for step, payload in rec.stimuli:
        t_s = float(stim_cls.FromString(payload).header.t)
        if until_s is not None and t_s > until_s:
            break
        while i_rx < len(rec.rx) and rec.rx[i_rx][0] <= step:  # what the channel delivered by this step
            bus.publish(rx_key, rec.rx[i_rx][1])
            i_rx += 1
        bus.publish(stim_key, payload)
        now_act, rec_act = acts.get(step), rec.acts.get(step)
        diffs += compare_step(step, t_s, rec_act, now_act, rec.txs.get(step, []), txs.get(step, []))
        ra = _vec(pb.ActuatorCommand.FromString(rec_act).accel_mps2) if rec_act else (math.nan,) * 3
        na = _vec(pb.ActuatorCommand.FromString(now_act).accel_mps2) if now_act else (math.nan,) * 3
        accel.append((step, t_s, *ra, *na))
        n += 1
    del node
    return ReflyResult(sid=rec.sid, steps=n, diffs=diffs, accel_delta=accel, wall_s=time.perf_counter() - t0)


def write_outputs(res: ReflyResult, out: Path) -> list[Path]:
    """DIR/commands.csv (recorded and re-flown acceleration per step, and their difference),
    DIR/divergences.csv (every differing field) and DIR/command-difference.png (|delta a| over time)."""
    out.mkdir(parents=True, exist_ok=True)
    table = out / "commands.csv"
    with table.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "t_s", "recorded_ax", "recorded_ay", "recorded_az", "now_ax", "now_ay", "now_az",
                    "delta_norm_mps2"])
        for step, t, *a in res.accel_delta:
            w.writerow([step, repr(t), *map(repr, a), repr(_delta_norm(a))])
    div = out / "divergences.csv"
    with div.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "t_s", "field", "recorded", "now"])
        for d in res.diffs:
            w.writerow([d.step, repr(d.t_s), d.field, repr(d.recorded), repr(d.now)])
    return [table, div, _figure(res, out / "command-difference.png")]


def _delta_norm(a: list[float]) -> float:
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a[:3], a[3:])))


def _figure(res: ReflyResult, path: Path) -> Path:
    from swarmhil.dashboards.figstyle import pyplot, save, time_axis  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    plt = pyplot()
    t_s = np.array([row[1] for row in res.accel_delta] + ([] if res.first is None else [res.first.t_s]), dtype=float)
    d = [_delta_norm(list(row[2:])) for row in res.accel_delta]
    t_shown, label = time_axis(t_s)
    fig, ax = plt.subplots(figsize=(7, 2.6))
    ax.plot(t_shown[:len(d)], d, lw=0.8)
    if res.first is not None:
        ax.axvline(t_shown[-1], color="C3", lw=0.8, ls="--", label=f"first divergence, step {res.first.step}")
        ax.legend(loc="upper left")
    ax.set_xlabel(label)
    ax.set_ylabel("|a_now - a_recorded| [m/s²]")
    ax.set_title(f"{res.sid}: re-flown command against the recorded one ({res.steps} steps)")
    save(fig, path)
    return path
