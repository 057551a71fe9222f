"""Issue 16: bus/truth_wire.py writes the plant's Truth byte for byte as protobuf's SerializeToString,
on random truths (zeros, -0.0, NaN, inf, dead bodies, ids of every length) and on recorded ones."""
from __future__ import annotations

import numpy as np
import pytest

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.truth_wire import HeaderEncoder, TickEncoder, TruthEncoder, encode_header, varint


def _protobuf(run, source, step, t, seq, u, a, n, ids, kinds, pos, vel, dv, alive, acc, roe) -> bytes:
    """The message as plant/node.py built it before the encoder (each field assigned)."""
    truth = pb.Truth(header=pb.Header(run=run, source=source, step=step, t=t, seq=seq), u_rad=u,
                     semi_major_axis_m=a, mean_motion_radps=n)
    for sid, kind, d, al, r, p, v, c in zip(ids, kinds, dv.tolist(), alive.tolist(), roe.tolist(), pos.tolist(),
                                            vel.tolist(), acc.tolist()):
        b = truth.bodies.add(id=sid, kind=kind, delta_v_mps=d, alive=al, roe_m=r)
        b.position_m.x, b.position_m.y, b.position_m.z = p
        b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z = v
        b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z = c
    return truth.SerializeToString()


SPECIAL = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, -1.0, 1e300])


def _values(rng: np.random.Generator, shape: tuple[int, ...], p_special: float) -> np.ndarray:
    x = rng.normal(scale=10.0 ** rng.integers(-8, 6), size=shape)
    pick = rng.random(shape) < p_special
    x[pick] = rng.choice(SPECIAL, size=int(pick.sum()))
    return x


def test_random_truths_equal_protobuf() -> None:
    rng = np.random.default_rng(16)
    for case in range(600):
        n = int(rng.integers(0, 25))
        if case % 7 == 0:  # ids and kinds of every length, incl. empty, non-ASCII and a 2-byte body length
            ids = ["".join(rng.choice(list("abcé01_"), size=int(rng.integers(0, 140)))) for _ in range(n)]
            kinds = [str(rng.choice(["", "spacecraft", "target", "ü" * 3])) for _ in range(n)]
        else:
            ids, kinds = [f"sc{i + 1:02d}" for i in range(n)], ["spacecraft"] * n
        p_special = float(rng.choice([0.0, 0.05, 0.5, 1.0]))
        pos, vel, acc = (_values(rng, (n, 3), p_special) for _ in range(3))
        if case % 5 == 0:
            acc[:] = 0.0  # no command (drift)
        dv, roe = _values(rng, (n,), p_special), _values(rng, (n, 6), p_special)
        alive = rng.random(n) < 0.8
        run, source = str(rng.choice(["", "r", "sabatini-20-20261201T000000-ab12"])), str(rng.choice(["", "plant"]))
        step, seq = int(rng.choice([0, 1, 127, 128, 8640, 2**40])), int(rng.choice([0, 5, 300]))
        t, u, a, nn = (float(x) for x in _values(rng, (4,), p_special))
        want = _protobuf(run, source, step, t, seq, u, a, nn, ids, kinds, pos, vel, dv, alive, acc, roe)
        enc = TruthEncoder(ids, kinds)
        got = enc.encode(encode_header(run, source, step, t, seq), u, a, nn, pos, vel, dv, alive, acc, roe)
        assert got == want, f"case {case}"
        # the encoder is reused step after step: a second truth through the same object
        pos2 = _values(rng, (n, 3), 0.3)
        want2 = _protobuf(run, source, step + 1, t, seq + 1, u, a, nn, ids, kinds, pos2, vel, dv, ~alive, acc, roe)
        assert enc.encode(encode_header(run, source, step + 1, t, seq + 1), u, a, nn, pos2, vel, dv, ~alive, acc,
                          roe) == want2
        # the same fields present, other values: the kept layout of the first pattern
        pos3, vel3, dv3, acc3 = 3.0 * pos, -vel, 0.5 * dv, acc * 7.0
        want3 = _protobuf(run, source, step, t, seq, u, a, nn, ids, kinds, pos3, vel3, dv3, alive, acc3, roe)
        assert enc.encode(encode_header(run, source, step, t, seq), u, a, nn, pos3, vel3, dv3, alive, acc3, roe) == want3


def test_more_patterns_than_kept(monkeypatch) -> None:
    import swarmhil.bus.truth_wire as tw

    monkeypatch.setattr(tw, "MAX_PLANS", 3)
    rng = np.random.default_rng(3)
    ids = [f"sc{i}" for i in range(6)]
    enc = TruthEncoder(ids)
    for step in range(40):
        pos, vel, acc = (_values(rng, (6, 3), 0.4) for _ in range(3))
        dv, roe, alive = _values(rng, (6,), 0.4), _values(rng, (6, 6), 0.1), rng.random(6) < 0.5
        want = _protobuf("r", "plant", step, 1.0, step, 0.5, 7e6, 1e-3, ids, ["spacecraft"] * 6, pos, vel, dv, alive,
                         acc, roe)
        assert enc.encode(encode_header("r", "plant", step, 1.0, step), 0.5, 7e6, 1e-3, pos, vel, dv, alive, acc,
                          roe) == want
        assert len(enc._plans) <= 3


def test_header_and_varint_equal_protobuf() -> None:
    # hand-encoded (base 128, least significant group first, high bit = more follows)
    assert varint(0) == b"\x00" and varint(1) == b"\x01" and varint(127) == b"\x7f"
    assert varint(128) == b"\x80\x01" and varint(300) == b"\xac\x02" and varint(16383) == b"\xff\x7f"
    assert varint(16384) == b"\x80\x80\x01" and varint(2**64 - 1) == b"\xff" * 9 + b"\x01"
    # protobuf's own: a uint64 field after its 1-byte tag; 0 as the length of an empty sub-message
    # (a uint64 of 0 is not written at all in proto3, so it cannot show varint(0))
    assert pb.Truth(header=pb.Header()).SerializeToString() == b"\x0a" + varint(0)
    for v in (1, 127, 128, 300, 5000, 16383, 16384, 2**35, 2**64 - 1):
        assert varint(v) == pb.Header(step=v).SerializeToString()[1:], v
    for t in (0.0, -0.0, 1.5, np.nan, -np.inf):
        for run, source, step, seq in (("run", "plant", 3, 0), ("", "", 0, 7), ("rün", "p", 2**40, 128)):
            want = pb.Header(run=run, source=source, step=step, t=t, seq=seq).SerializeToString()
            assert encode_header(run, source, step, t, seq) == want == HeaderEncoder(run, source)(step, t, seq)


def _recorded_truths(tmp_path, scenario: str, duration_s: float) -> list[bytes]:
    """The truth payloads of the scenario's in-process run (truth recorded: the batch mode where it can)."""
    from mcap.reader import make_reader

    from conftest import SCENARIOS
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    sc = load_scenario(SCENARIOS / f"{scenario}.toml").with_overrides(duration_s=duration_s)
    run_in_process(sc, tmp_path, "wire", record="truth")
    with open(tmp_path / "run.mcap", "rb") as f:
        return [m.data for _s, ch, m in make_reader(f).iter_messages() if ch.topic == "truth"]


@pytest.mark.parametrize("scenario", ["sabatini-20", "drift-20"])
def test_recorded_truths_equal_protobuf(tmp_path, scenario) -> None:
    """Every truth of a run (written by the encoder) is what protobuf makes of its own values."""
    truths = _recorded_truths(tmp_path, scenario, 300.0)
    assert len(truths) == 31
    for data in truths:
        m = pb.Truth.FromString(data)
        h, bs = m.header, list(m.bodies)
        arr = lambda f: np.array([f(b) for b in bs], dtype=float).reshape(len(bs), -1)  # noqa: E731
        vec = lambda name: arr(lambda b: [getattr(getattr(b, name), c) for c in "xyz"])  # noqa: E731
        pos, vel, acc = vec("position_m"), vec("velocity_mps"), vec("accel_cmd_mps2")
        dv, roe = arr(lambda b: b.delta_v_mps)[:, 0], arr(lambda b: list(b.roe_m))
        alive = np.array([b.alive for b in bs])
        ids, kinds = [b.id for b in bs], [b.kind for b in bs]
        args = (m.u_rad, m.semi_major_axis_m, m.mean_motion_radps)
        assert _protobuf(h.run, h.source, h.step, h.t, h.seq, *args, ids, kinds, pos, vel, dv, alive, acc, roe) == data
        assert TruthEncoder(ids, kinds).encode(encode_header(h.run, h.source, h.step, h.t, h.seq), *args, pos, vel,
                                               dv, alive, acc, roe) == data


@pytest.mark.parametrize("max_plans", [256, 5])
def test_new_combinations_of_seen_rows_equal_protobuf(monkeypatch, max_plans: int) -> None:
    """A new pattern made of bodies that each showed their pattern before (commanded components
    exactly zero now and then, body by body, as in tersoff-6) is written from the bodies' kept parts
    (issue 29): the same bytes as protobuf, with far fewer full plans than patterns."""
    import swarmhil.bus.truth_wire as tw

    monkeypatch.setattr(tw, "MAX_PLANS", max_plans)
    rng = np.random.default_rng(29)
    ids = [f"sc{i}" for i in range(6)]
    enc = TruthEncoder(ids)
    plans = 0
    full = enc._plan

    def counted(pr: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        nonlocal plans
        plans += 1
        return full(pr, rows)

    monkeypatch.setattr(enc, "_plan", counted)
    for step in range(300):
        pos, vel, acc = (_values(rng, (6, 3), 0.0) for _ in range(3))
        acc[rng.random((6, 3)) < 0.3] = rng.choice([0.0, -0.0])
        dv, roe, alive = _values(rng, (6,), 0.0), _values(rng, (6, 6), 0.0), rng.random(6) < 0.9
        want = _protobuf("r", "plant", step, 1.0, step, 0.5, 7e6, 1e-3, ids, ["spacecraft"] * 6, pos, vel, dv, alive,
                         acc, roe)
        assert enc.encode(encode_header("r", "plant", step, 1.0, step), 0.5, 7e6, 1e-3, pos, vel, dv, alive, acc,
                          roe) == want, step
        assert len(enc._plans) <= max_plans
    if max_plans > 100:
        assert plans < 100 < len(enc._plans), (plans, len(enc._plans))


def _with_bodies(data: bytes, bodies: list[tuple[str, str, list[float], list[float], list[float], list[float]]]) -> bytes:
    """A serialised spacecraft Truth with non-agent bodies added after the spacecraft as plant/node.py
    `_add_mission_truth` adds them (id, kind, alive, position, velocity, attitude, angular velocity)."""
    truth = pb.Truth.FromString(data)
    for bid, kind, p, v, q, w in bodies:
        b = truth.bodies.add(id=bid, kind=kind, alive=True)
        b.position_m.x, b.position_m.y, b.position_m.z = p
        b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z = v
        b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z = q
        b.angular_velocity_radps.x, b.angular_velocity_radps.y, b.angular_velocity_radps.z = w
    return truth.SerializeToString()


def test_truths_with_bodies_equal_protobuf() -> None:
    """Issue 29: the encoder's truth with `more_bodies` (each body's `body_entry` of its own message,
    plant/node.py `_body_state`) is the message with those bodies added after the spacecraft."""
    from swarmhil.bus.truth_wire import body_entry
    from swarmhil.plant.node import PlantNode

    rng = np.random.default_rng(29)
    for case in range(300):
        n, nb = int(rng.integers(0, 8)), int(rng.integers(0, 4))
        ids, kinds = [f"sc{i}" for i in range(n)], ["spacecraft"] * n
        p_special = float(rng.choice([0.0, 0.05, 0.5]))
        pos, vel, acc = (_values(rng, (n, 3), p_special) for _ in range(3))
        dv, roe, alive = _values(rng, (n,), p_special), _values(rng, (n, 6), p_special), rng.random(n) < 0.8
        u, a, nn = (float(x) for x in _values(rng, (3,), p_special))
        bodies = [(str(rng.choice(["tsat", "", "ü"])), str(rng.choice(["target", ""])),
                   *(_values(rng, (k,), p_special).tolist() for k in (3, 3, 4, 3))) for _ in range(nb)]
        base = _protobuf("r", "plant", case, 0.1 * case, case, u, a, nn, ids, kinds, pos, vel, dv, alive, acc, roe)
        spec = type("S", (), {})
        more = []
        for bid, kind, p, v, q, w in bodies:
            bt = type("BT", (), {})()
            bt.spec, bt.spec.id, bt.spec.kind = spec(), bid, kind
            bt.position_m, bt.velocity_mps, bt.attitude_q, bt.angular_velocity_radps = (np.array(x) for x in (p, v, q, w))
            more.append(body_entry(PlantNode._body_state(bt).SerializeToString()))
        got = TruthEncoder(ids, kinds).encode(encode_header("r", "plant", case, 0.1 * case, case), u, a, nn, pos, vel, dv,
                                              alive, acc, roe, b"".join(more))
        assert got == _with_bodies(base, bodies), f"case {case}"


def test_recorded_truths_with_a_target_equal_protobuf(tmp_path) -> None:
    """Every truth of surround-6 (six servicers, a leader and the target body; written by the encoder
    with the target's entry after them) is what the message built field by field makes of its values."""
    truths = _recorded_truths(tmp_path, "surround-6", 20.0)
    assert len(truths) == 201
    for data in truths:
        m = pb.Truth.FromString(data)
        h, sc_bodies = m.header, [b for b in m.bodies if b.kind == "spacecraft"]
        others = [b for b in m.bodies if b.kind != "spacecraft"]
        assert [b.kind for b in m.bodies] == ["spacecraft"] * 7 + ["target"] and len(others) == 1
        arr = lambda f: np.array([f(b) for b in sc_bodies], dtype=float).reshape(len(sc_bodies), -1)  # noqa: E731
        vec = lambda name: arr(lambda b: [getattr(getattr(b, name), c) for c in "xyz"])  # noqa: E731
        base = _protobuf(h.run, h.source, h.step, h.t, h.seq, m.u_rad, m.semi_major_axis_m, m.mean_motion_radps,
                         [b.id for b in sc_bodies], ["spacecraft"] * 7, vec("position_m"), vec("velocity_mps"),
                         arr(lambda b: b.delta_v_mps)[:, 0], np.array([b.alive for b in sc_bodies]), vec("accel_cmd_mps2"),
                         arr(lambda b: list(b.roe_m)))
        t = others[0]
        assert _with_bodies(base, [(t.id, t.kind, [t.position_m.x, t.position_m.y, t.position_m.z],
                                    [t.velocity_mps.x, t.velocity_mps.y, t.velocity_mps.z],
                                    [t.attitude.w, t.attitude.x, t.attitude.y, t.attitude.z],
                                    [t.angular_velocity_radps.x, t.angular_velocity_radps.y, t.angular_velocity_radps.z])]) == data


def test_a_large_swarm_plans_only_its_new_bodies(monkeypatch) -> None:
    """300 bodies, a few of which show a new pattern of present fields every step (as in a swarm of
    hundreds, where some commanded component is exactly zero somewhere almost every step): the same
    bytes as protobuf, and only the bodies with a new pattern are planned, not all of them each time."""
    rng = np.random.default_rng(39)
    n = 300
    ids = [f"sc{i:03d}" for i in range(n)]
    enc = TruthEncoder(ids)
    planned = []
    full = enc._plan

    def counted(pr: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        planned.append(len(pr))
        return full(pr, rows)

    monkeypatch.setattr(enc, "_plan", counted)
    pos, vel, acc = (_values(rng, (n, 3), 0.0) for _ in range(3))
    dv, roe, alive = _values(rng, (n,), 0.0), _values(rng, (n, 6), 0.0), np.ones(n, dtype=bool)
    for step in range(60):
        acc = _values(rng, (n, 3), 0.0)
        acc[rng.integers(n, size=3), rng.integers(3, size=3)] = rng.choice([0.0, -0.0])
        alive[rng.integers(n)] = step % 7 != 3
        want = _protobuf("r", "plant", step, 1.0, step, 0.5, 7e6, 1e-3, ids, ["spacecraft"] * n, pos, vel, dv, alive,
                         acc, roe)
        assert enc.encode(encode_header("r", "plant", step, 1.0, step), 0.5, 7e6, 1e-3, pos, vel, dv, alive, acc,
                          roe) == want, step
    assert planned[0] == n and len(planned) > 30 and max(planned[1:]) <= 4, planned


def test_ticks_equal_protobuf() -> None:
    """The plant's tick (plant/node.py) written by TickEncoder: protobuf's bytes, with the alive flags
    changing, steps and sequence numbers of several varint lengths, +0.0 / -0.0 / NaN times, final."""
    rng = np.random.default_rng(5)
    ids = [f"sc{i:02d}" for i in range(12)] + ["", "x" * 140]
    enc = TickEncoder("run-t", ids)
    for k in range(200):
        alive = rng.random(len(ids)) < (0.9 if k % 3 else 0.5)
        step, seq = int(rng.choice([0, k, 300, 2**33])), int(rng.choice([0, k, 2**20]))
        t = float(rng.choice([0.0, -0.0, 10.0 * k, np.nan]))
        u, step_s = float(rng.choice([0.0, -0.0, rng.standard_normal()])), float(rng.choice([10.0, 0.0]))
        final = bool(k % 7 == 0)
        msg = pb.Tick(header=pb.Header(run="run-t", source="plant", step=step, t=t, seq=seq), step_s=step_s, u_rad=u,
                      alive=[s for s, a in zip(ids, alive) if a], final=final)
        assert enc.encode(step, t, seq, step_s, u, alive, final) == msg.SerializeToString()
