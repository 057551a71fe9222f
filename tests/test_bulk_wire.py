"""bus/bulk_wire.py: the batch mode's packets built from arrays are protobuf's own bytes.

Each encoder is checked against `SerializeToString` of the message built field by field as the
per-agent path builds it (plant/sensing/builtin.py RelKind.stimuli, agent/node.py AgentNode.handle),
on random values that include +0.0 (omitted), -0.0, NaN and inf (written), empty neighbour lists,
strings of every length class and varints of several bytes, through a new plan and a kept one."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.bulk_wire import AgentMessages, Pool, RelStimuli, split, varint_bytes
from swarmhil.bus.truth_wire import varint


def _values(rng: np.random.Generator, shape: tuple[int, ...], dense: bool = False) -> np.ndarray:
    """Random doubles; +0.0 (omitted) among them unless `dense` (every field written: the encoders'
    paths without masks)."""
    v = np.asarray(rng.standard_normal(shape) * 10.0 ** rng.integers(-6, 6, shape), dtype=float)
    pick = np.asarray(rng.random(shape))
    v[pick < 0.15] = 1.5 if dense else 0.0
    v[(pick >= 0.15) & (pick < 0.2)] = -0.0
    v[(pick >= 0.2) & (pick < 0.23)] = np.nan
    v[(pick >= 0.23) & (pick < 0.25)] = -np.inf
    return v


def test_varints_are_protobufs() -> None:
    vals = np.array([0, 1, 127, 128, 300, 16383, 16384, 2**21, 2**35 + 5, 2**63 + 7, 2**64 - 1], dtype=np.uint64)
    data, lens = varint_bytes(vals)
    for v, d, n in zip(vals.tolist(), data, lens.tolist()):
        assert d[:n].tobytes() == varint(v)
        assert pb.Header(seq=v).SerializeToString() == (b"\x28" + varint(v) if v else b"")


def _check_stimuli(enc: RelStimuli, ids: list[str], step: int, t: float, seq: np.ndarray, u: float, off: np.ndarray,
                   nb: np.ndarray, rp: np.ndarray, rv: np.ndarray) -> None:
    blob, ends = enc.encode(step, t, seq, u, off, nb, rp, rv)
    got = split(blob, ends)
    assert len(got) == len(off) - 1
    for i, b in enumerate(got):
        m = pb.RelStimulus(header=pb.Header(run="run-1", source="plant", step=step, t=t, seq=int(seq[i])), u_rad=u)
        for k in range(off[i], off[i + 1]):
            e = m.neighbours.add(id=ids[nb[k]])
            e.position_m.x, e.position_m.y, e.position_m.z = rp[k].tolist()
            e.velocity_mps.x, e.velocity_mps.y, e.velocity_mps.z = rv[k].tolist()
        assert b == m.SerializeToString()


def _check_agents(enc: AgentMessages, ids: list[str], names: list[str], step: int, t: float, seq: np.ndarray,
                  rows: np.ndarray, acc: np.ndarray, modes: list[str], cs: float, off: np.ndarray, dec: tuple) -> None:
    nb, labels, dmin, roe, dacc = dec
    blob, ends = enc.commands(step, t, seq, rows, acc).encode()
    for i, b in enumerate(split(blob, ends)):
        hdr = pb.Header(run="run-1", source=ids[rows[i]], step=step, t=t, seq=int(seq[i]))
        m = pb.ActuatorCommand(header=hdr, accel_mps2=pb.Vector3(x=acc[i, 0], y=acc[i, 1], z=acc[i, 2]),
                               controller=names[rows[i]])
        assert b == m.SerializeToString()
    names_or_idx = nb if step % 2 else [ids[k] for k in nb]
    table = sorted(set(labels))
    blob, ends = enc.telemetry(step, t, seq, rows, modes, acc, cs, off, names_or_idx, table,
                               np.array([table.index(b) for b in labels], dtype=np.int64), dmin, roe, dacc).encode()
    for i, b in enumerate(split(blob, ends)):
        hdr = pb.Header(run="run-1", source=ids[rows[i]], step=step, t=t, seq=int(seq[i]))
        m = pb.Telemetry(header=hdr, mode=modes[i], controller=names[rows[i]],
                         accel_mps2=pb.Vector3(x=acc[i, 0], y=acc[i, 1], z=acc[i, 2]), compute_s=cs)
        for k in range(off[i], off[i + 1]):
            q = m.decisions.add(neighbour=ids[nb[k]], behaviour=labels[k], d_min_m=float(dmin[k]),
                                roe_rel_m=roe[k].tolist()).accel_mps2
            q.x, q.y, q.z = dacc[k].tolist()
        assert b == m.SerializeToString()


@pytest.mark.parametrize("dense", [False, True], ids=["zeros", "dense"])
@pytest.mark.parametrize("seed", range(6))
def test_stimuli_commands_telemetry_as_protobuf(seed: int, dense: bool) -> None:
    """Random layouts, each encoded twice with new values (the second time from the kept plan when
    the layout is the same) and once by fresh encoders (a new plan)."""
    rng = np.random.default_rng(seed)
    # ids of one length (string fields without masks) or of many
    ids = [f"sc{i:02d}" for i in range(15)] + ([] if dense and seed % 2 else ["x" * 200, "", "é" * 70])
    names = [str(rng.choice(["sabatini"] if dense else ["sabatini", "", "c" * 150])) for _ in ids]
    shared = Pool()
    stim, agents = RelStimuli(shared, "run-1", "plant", ids), AgentMessages(shared, "run-1", ids, names)
    for _layout in range(3):
        r = int(rng.integers(0, 12))
        counts = rng.integers(0, 6, r)
        counts[rng.random(r) < 0.3] = 0
        off = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        p = int(off[-1])
        nb = rng.integers(0, len(ids), p)
        rows = np.sort(rng.choice(len(ids), r, replace=False))
        modes = [str(rng.choice(["search", "alignment", "", "m" * 130] if not dense else ["search", "alignment"])) for _ in range(r)]
        labels = [str(rng.choice(["collision_avoidance", "alignment", "", "b" * 140])) for _ in range(p)]
        for again in range(2):
            step = int(rng.choice([0, 1, 200, 2**40] if not dense else [7 + again]))
            t = float(rng.choice([0.0, -0.0, 10.0 * step, np.nan] if not dense else [10.0 * step]))
            u = float(_values(rng, (1,), dense)[0])
            seq = (rng.choice([5, 6], r) if dense else rng.choice([0, 5, 130, 2**33], r)).astype(np.uint64)
            rp, rv = _values(rng, (p, 3), dense), _values(rng, (p, 3), dense)
            acc = _values(rng, (r, 3), dense)
            dec = (nb, labels, _values(rng, (p,), dense), _values(rng, (p, 6), dense), _values(rng, (p, 3), dense))
            cs = float(abs(_values(rng, (1,), dense)[0]))
            for s_enc, a_enc in ((stim, agents), (RelStimuli(Pool(), "run-1", "plant", ids), AgentMessages(Pool(), "run-1", ids, names))):
                _check_stimuli(s_enc, ids, step, t, seq, u, off, nb, rp, rv)
                _check_agents(a_enc, ids, names, step, t, seq, rows, acc, modes, cs, off, dec)
    if dense:  # (the second encoding of a dense layout is often the same layout: a kept plan)
        assert stim.plans.built < 6 or agents.tm_plans.built < 6


@pytest.mark.parametrize("dense", [False, True], ids=["zeros", "dense"])
def test_measurements_with_items_as_protobuf(dense: bool) -> None:
    """`Measurements` (neighbours, then named flat arrays: the `relative` kind's own state) as
    plant/sensing/builtin.py RelativeKind.stimulus builds them with bus/codec.py add_measurement."""
    from swarmhil.bus.codec import add_measurement

    rng = np.random.default_rng(11)
    ids = [f"sc{i:02d}" for i in range(6)]
    enc = RelStimuli(Pool(), "run-m", "plant", ids)
    for step in range(1, 12):
        r = int(rng.integers(1, 6))
        counts = rng.integers(0, 4, r)
        off = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        p = int(off[-1])
        nb = rng.integers(0, len(ids), p)
        rp, rv = _values(rng, (p, 3), dense), _values(rng, (p, 3), dense)
        items = {"own_position_m": _values(rng, (r, 3), dense), "own_velocity_mps": _values(rng, (r, 3), dense),
                 "none": np.zeros((r, 0))}
        seq = np.full(r, step, dtype=np.uint64)
        blob, ends = enc.prepare(step, 5.0 * step, seq, 0.25, off, nb, rp, rv, items).encode()
        for i, b in enumerate(split(blob, ends)):
            m = pb.Measurements(header=pb.Header(run="run-m", source="plant", step=step, t=5.0 * step, seq=step), u_rad=0.25)
            for k in range(off[i], off[i + 1]):
                e = m.neighbours.add(id=ids[nb[k]])
                e.position_m.x, e.position_m.y, e.position_m.z = rp[k].tolist()
                e.velocity_mps.x, e.velocity_mps.y, e.velocity_mps.z = rv[k].tolist()
            for name, v in items.items():
                add_measurement(m, name, v[i])
            assert b == m.SerializeToString()


@pytest.mark.parametrize("dense", [False, True], ids=["zeros", "dense"])
def test_measurements_with_each_observers_items_as_protobuf(dense: bool) -> None:
    """`Measurements` whose items differ from observer to observer, with subjects (papers 003 and
    004: a mission kind's batch form, RelBatch.named's `name/subject` dicts), as the kinds'
    `stimulus` builds them with bus/codec.py add_measurement: items of several lengths and shapes
    (empty too; paper 000's landmarks are (K, 3)), observers without any, layouts that come back."""
    from swarmhil.bus.codec import add_measurement

    rng = np.random.default_rng(12)
    ids = ["lsat", "ssat1", "ssat2", "ssat3"]
    names = [("p003.target_rel.position_m", "tsat"), ("p004.d_m", "ssat2"), ("p004.y_m", "defunct"), ("own", "")]
    enc = RelStimuli(Pool(), "run-n", "plant", ids)
    for step in range(1, 16):
        r = int(rng.integers(1, 5))
        named = []
        for _i in range(r):
            chosen = [names[j] for j in sorted(rng.choice(len(names), int(rng.integers(0, 4)), replace=False))]
            shapes = [(int(rng.integers(0, 4)),), (int(rng.integers(0, 3)), 3), (1, 2, 2), ()]
            pick = int(rng.integers(0, 4)) if step % 3 == 0 else 0  # (flat arrays only in two steps of three: a plan)
            named.append({f"{n}/{s}" if s else n: _values(rng, shapes[pick], dense) for n, s in chosen})
        off = np.zeros(r + 1, dtype=np.int64)
        seq = rng.integers(0, 300, r).astype(np.uint64)
        blob, ends = enc.prepare(step, 0.1 * step, seq, -0.5, off, np.zeros(0, dtype=np.int64), np.zeros((0, 3)),
                                 np.zeros((0, 3)), named).encode()
        got = split(blob, ends)
        assert len(got) == r
        for i, b in enumerate(got):
            m = pb.Measurements(header=pb.Header(run="run-n", source="plant", step=step, t=0.1 * step, seq=int(seq[i])),
                                u_rad=-0.5)
            for key, v in named[i].items():
                name, _, subject = key.rpartition("/") if "/" in key else (key, "", "")
                add_measurement(m, name, v, subject)
            assert b == m.SerializeToString()


def test_isl_packets_and_commands_with_transmissions_as_protobuf() -> None:
    """`IslPacket`s as agent/node.py `isl_packet` and link/node.py `_publish` build them (broadcast
    and addressed, empty and long payloads, sent_t 0), and `ActuatorCommand.isl_tx_count`."""
    from swarmhil.bus.bulk_wire import IslPackets

    rng = np.random.default_rng(13)
    ids = ["lsat", "ssat1", "ssat2"]
    pool = Pool()
    enc, agents = IslPackets(pool, "run-i"), AgentMessages(pool, "run-i", ids, ["p003-leader", "p003-servicer", "p003-servicer"])
    for step in list(range(0, 6)) + [200, 70000]:
        n = int(rng.integers(0, 6))
        seq = rng.integers(0, 2 ** int(rng.integers(1, 20)), n).tolist()
        sources = [str(rng.choice(ids + ["channel"])) for _ in range(n)]
        srcs = [str(rng.choice(ids)) for _ in range(n)]
        dsts = [str(rng.choice(ids + [""])) for _ in range(n)]
        types = [str(rng.choice(["p003.tt", "p003.ct", ""])) for _ in range(n)]
        payloads = [rng.bytes(int(rng.choice([0, 1, 41, 454]))) for _ in range(n)]
        t = 0.1 * step
        sent = [t if rng.random() < 0.7 else 0.0 for _ in range(n)]
        for _again in range(2):  # a new plan, then the kept one
            blob, ends = enc.prepare(step, t, seq, sources, srcs, dsts, types, payloads, sent).encode()
            got = split(blob, ends)
            assert len(got) == n
            for i, b in enumerate(got):
                want = pb.IslPacket(header=pb.Header(run="run-i", source=sources[i], step=step, t=t, seq=seq[i]),
                                    src=srcs[i], dst=dsts[i], type=types[i], payload=payloads[i], sent_t=sent[i])
                assert b == want.SerializeToString()
        rows = np.flatnonzero(rng.random(3) < 0.8)
        acc, count = _values(rng, (len(rows), 3)), rng.integers(0, 3, len(rows))
        q = np.full(len(rows), step, dtype=np.uint64)
        blob, ends = agents.commands(step, t, q, rows, acc, count).encode()
        for i, b in enumerate(split(blob, ends)):
            a = pb.Vector3(x=acc[i, 0], y=acc[i, 1], z=acc[i, 2])
            want = pb.ActuatorCommand(header=pb.Header(run="run-i", source=ids[rows[i]], step=step, t=t, seq=step),
                                      accel_mps2=a, controller=agents.controllers.strings[rows[i]],
                                      isl_tx_count=int(count[i]))
            assert b == want.SerializeToString()
