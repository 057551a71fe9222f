"""bus/bulk_wire.py: the batch mode's packets built from arrays are protobuf's own bytes.

Each encoder is checked against `SerializeToString` of the message built field by field as the
per-agent path builds it (plant/sensing/builtin.py RelKind.stimuli, agent/node.py AgentNode.handle),
on random values that include +0.0 (omitted), -0.0, NaN and inf (written), empty neighbour lists,
strings of every length class and varints of several bytes."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.bulk_wire import (Rows, StringCache, StringTable, actuator_commands, header_rows, neighbour_decisions,
                                    rel_stimuli, split, telemetry, varint_bytes)
from swarmhil.bus.truth_wire import _string, varint


def _values(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    v = rng.standard_normal(shape) * 10.0 ** rng.integers(-6, 6, shape)
    pick = rng.random(shape)
    v[pick < 0.15] = 0.0
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


@pytest.mark.parametrize("seed", range(6))
def test_stimuli_commands_telemetry_as_protobuf(seed: int) -> None:
    rng = np.random.default_rng(seed)
    ids = [f"sc{i:02d}" for i in range(15)] + ["x" * 200, "", "é" * 70]
    table = StringTable(0x0A, ids)
    r = int(rng.integers(0, 12))
    counts = rng.integers(0, 6, r)
    counts[rng.random(r) < 0.3] = 0
    off = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    p = int(off[-1])
    nb = rng.integers(0, len(ids), p)
    rp, rv = _values(rng, (p, 3)), _values(rng, (p, 3))
    step = int(rng.choice([0, 1, 200, 2**40]))
    t = float(rng.choice([0.0, -0.0, 10.0 * step, np.nan]))
    u = float(_values(rng, (1,))[0])
    seq = rng.choice([0, 5, 130, 2**33], r).astype(np.uint64)
    src = rng.integers(0, len(ids), r)
    run_src = _string(0x0A, "run-1") + _string(0x12, "plant")

    blob, ends = rel_stimuli(header_rows(r, run_src, step, t, seq), u, off, table, nb, rp, rv)
    for i, got in enumerate(split(blob, ends)):
        m = pb.RelStimulus(header=pb.Header(run="run-1", source="plant", step=step, t=t, seq=int(seq[i])), u_rad=u)
        for k in range(off[i], off[i + 1]):
            e = m.neighbours.add(id=ids[nb[k]])
            e.position_m.x, e.position_m.y, e.position_m.z = rp[k].tolist()
            e.velocity_mps.x, e.velocity_mps.y, e.velocity_mps.z = rv[k].tolist()
        assert got == m.SerializeToString()

    run_only = _string(0x0A, "run-1")
    ctrl = StringCache(0x1A)
    names = [str(rng.choice(["sabatini", "", "c" * 150])) for _ in range(r)]
    acc = _values(rng, (r, 3))
    tq = _values(rng, (r, 3))
    tq[rng.random(r) < 0.4] = np.nan  # no torque
    tx = rng.choice([0, 1, 300], r)
    for torque in (None, tq):
        blob, ends = actuator_commands(header_rows(r, run_only, step, t, seq, (table_src := StringTable(0x12, ids), src)),
                                       acc, ctrl.rows(names), tx, torque)
        for i, got in enumerate(split(blob, ends)):
            hdr = pb.Header(run="run-1", source=ids[src[i]], step=step, t=t, seq=int(seq[i]))
            m = pb.ActuatorCommand(header=hdr, accel_mps2=pb.Vector3(x=acc[i, 0], y=acc[i, 1], z=acc[i, 2]),
                                   controller=names[i], isl_tx_count=int(tx[i]))
            if torque is not None and not np.isnan(torque[i]).all():
                m.torque_nm.CopyFrom(pb.Vector3(x=tq[i, 0], y=tq[i, 1], z=tq[i, 2]))
            assert got == m.SerializeToString()

    behaviours = StringCache(0x12)
    labels = [str(rng.choice(["collision_avoidance", "alignment", "", "b" * 140])) for _ in range(p)]
    dmin, roe, dacc = _values(rng, (p,)), _values(rng, (p, 6)), _values(rng, (p, 3))
    dec = neighbour_decisions(StringTable(0x0A, ids), nb, *behaviours.rows(labels), dmin, roe, dacc)
    modes = StringCache(0x12)
    mode_names = [str(rng.choice(["search", "alignment", "", "fault"])) for _ in range(r)]
    cs, rej = np.abs(_values(rng, (r,))), rng.choice([0, 3, 2**20], r)
    blob, ends = telemetry(header_rows(r, run_only, step, t, seq, (table_src, src)), modes.rows(mode_names),
                           ctrl.rows(names),
                           (*dec, off), acc, cs, rej)
    for i, got in enumerate(split(blob, ends)):
        hdr = pb.Header(run="run-1", source=ids[src[i]], step=step, t=t, seq=int(seq[i]))
        m = pb.Telemetry(header=hdr, mode=mode_names[i], controller=names[i],
                         accel_mps2=pb.Vector3(x=acc[i, 0], y=acc[i, 1], z=acc[i, 2]), compute_s=cs[i],
                         rejected_packets=int(rej[i]))
        for k in range(off[i], off[i + 1]):
            q = m.decisions.add(neighbour=ids[nb[k]], behaviour=labels[k], d_min_m=float(dmin[k]),
                                roe_rel_m=roe[k].tolist()).accel_mps2
            q.x, q.y, q.z = dacc[k].tolist()
        assert got == m.SerializeToString()


def test_rows_of_nothing() -> None:
    assert Rows(0).const(b"ab").encode()[0] == b""
    blob, ends = Rows(3).encode()
    assert blob == b"" and ends.tolist() == [0, 0, 0, 0]
