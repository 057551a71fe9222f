#!/usr/bin/env python3
"""A second external flight computer for swarmhil, written from docs/hil.md and a join kit alone.

One file, one thread of control, no asyncio and no numpy: Zenoh callbacks only put the samples of
the spacecraft's two inbound keys on one queue (so link packets and stimuli keep their arrival
order), and the main loop decodes each stimulus, computes the built-in law and publishes the
command. The protobuf code is generated at start-up from the kit's own ``swarmhil.proto`` (grpcio-tools'
``protoc``) into a temporary directory, so nothing has to be built beforehand.

Usage::

    python fc2.py KIT_DIR [--connect ENDPOINT] [--delay-s S] [--no-telemetry] [--rejoin-margin-s S]

The laws (docs/hil.md "The built-in laws, to the bit"), IEEE double precision, in this order:

- ``null``: a = (0, 0, 0), mode ``coast``.
- ``drift-null``: da_i = (4 x_i) + ((2 vy_i) / n); m = mean(da_i) with numpy's pairwise summation;
  u = ((gain_per_s n) / 2) m; u_y = min(max(u, -a_max), a_max); a = (0, u_y, 0), mode ``drift-null``;
  no neighbour: a = (0, 0, 0), mode ``search``.

It imports nothing of swarmhil: only the standard library, eclipse-zenoh, protobuf and grpcio-tools.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import queue
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Any

import zenoh

PROG = "fc2"
ROUTER_GONE_S = 2.0
REJOIN_MARGIN_S = 5.0  # lockstep: no stimulus for stall_timeout_s + this after an answer = dropped
COLD: tuple[tuple[float, float, float], str] = ((0.0, 0.0, 0.0), "idle")  # no decision yet: no thrust
TLS_KEYS = {  # the kit's `tls` roles -> the Zenoh settings that name those files
    "ca": "transport/link/tls/root_ca_certificate",
    "cert": "transport/link/tls/connect_certificate",
    "key": "transport/link/tls/connect_private_key",
}  # docs/hil.md "When to leave": a client that sees its router gone may leave


class KitError(Exception):
    """A join kit that cannot be used: one line, naming the file and what is wrong."""


# --------------------------------------------------------------------------------------------
# The laws: pure functions of floats (no numpy), the arithmetic of docs/hil.md in its order.
# --------------------------------------------------------------------------------------------


def pairwise_sum(values: list[float], lo: int = 0, hi: int | None = None) -> float:
    """Sum values[lo:hi] the way numpy's float64 ``add.reduce`` does (its pairwise summation).

    Fewer than 8 values: left to right from 0.0. Up to 128: eight running sums over strides of 8,
    combined as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the remainder left to right.
    More: split at n/2 rounded down to a multiple of 8 and add the two halves' sums.
    """
    if hi is None:
        hi = len(values)
    n = hi - lo
    if n < 8:
        total = 0.0
        for i in range(lo, hi):
            total += values[i]
        return total
    if n <= 128:
        r = values[lo : lo + 8]
        i = lo + 8
        end = hi - (n % 8)
        while i < end:
            for j in range(8):
                r[j] += values[i + j]
            i += 8
        total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < hi:
            total += values[i]
            i += 1
        return total
    half = n // 2
    half -= half % 8
    return pairwise_sum(values, lo, lo + half) + pairwise_sum(values, lo + half, hi)


def mean_like_numpy(values: list[float]) -> float:
    """``np.mean`` of a float64 vector: (0.0 + pairwise sum) / N (numpy's reduction starts at 0.0)."""
    return (0.0 + pairwise_sum(values)) / len(values)


def drift_null(
    neighbours: list[tuple[float, float]], n: float, gain_per_s: float, max_accel_mps2: float
) -> tuple[tuple[float, float, float], str]:
    """The drift-null law on (x_i, vy_i) of each neighbour, in arrival order.

    da_i = (4.0 * x_i) + ((2.0 * vy_i) / n) is the pair's relative semi-major axis times a (the
    linearised relation of relative orbital elements, Hill/Clohessy-Wiltshire); the command drives
    the mean of the da_i to zero with u = ((gain_per_s * n) / 2.0) * m, saturated at max_accel_mps2.
    Returns the LVLH acceleration and the mode.
    """
    if not neighbours:
        return (0.0, 0.0, 0.0), "search"
    da = [(4.0 * x) + ((2.0 * vy) / n) for x, vy in neighbours]
    m = mean_like_numpy(da)
    u = ((gain_per_s * n) / 2.0) * m
    u_y = min(max(u, -max_accel_mps2), max_accel_mps2)
    return (0.0, u_y, 0.0), "drift-null"


@dataclass(frozen=True)
class Law:
    """The built-in law a kit's ``agent`` block names, with its parameters."""

    name: str
    mean_motion_radps: float
    gain_per_s: float = 1e-4
    max_accel_mps2: float = 1e-3

    def decide(self, neighbours: list[tuple[float, float]]) -> tuple[tuple[float, float, float], str]:
        """One decision: the command's acceleration (LVLH, m/s^2) and the mode."""
        if self.name == "null":
            return (0.0, 0.0, 0.0), "coast"
        return drift_null(neighbours, self.mean_motion_radps, self.gain_per_s, self.max_accel_mps2)


LAWS = ("null", "drift-null")


def law_from_kit(agent: dict[str, Any], where: str) -> Law:
    """The law of the kit's ``agent`` block, or KitError naming what this computer cannot fly."""
    name = agent.get("controller")
    if name not in LAWS:
        raise KitError(f"{where}: agent.controller {name!r} is not a law this flight computer flies ({', '.join(LAWS)})")
    kind = agent.get("sense_kind")
    if kind != "rel":
        raise KitError(f"{where}: agent.sense_kind {kind!r}: this flight computer reads only 'rel' stimuli")
    params = dict(agent.get("params") or {})
    unknown = sorted(set(params) - {"gain_per_s", "max_accel_mps2"})
    if name == "drift-null" and unknown:
        raise KitError(f"{where}: agent.params has {unknown}, which drift-null does not take")
    try:
        n = float(agent["orbit"]["mean_motion_radps"])
        law = Law(
            name=name,
            mean_motion_radps=n,
            gain_per_s=float(params.get("gain_per_s", 1e-4)),
            max_accel_mps2=float(params.get("max_accel_mps2", 1e-3)),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise KitError(f"{where}: agent block incomplete or not numeric ({exc!r})") from None
    if not n > 0.0:
        raise KitError(f"{where}: agent.orbit.mean_motion_radps must be > 0 (got {n})")
    return law


# --------------------------------------------------------------------------------------------
# The kit
# --------------------------------------------------------------------------------------------


@dataclass
class Kit:
    """What this computer takes from ``join.json``."""

    path: str
    run: str
    spacecraft: str
    keys: dict[str, str]
    token: str
    zenoh: dict[str, Any]
    proto: str
    mode: str
    steps: int
    decision_period_steps: int
    stall_timeout_s: float
    law: Law


def load_kit(kit_dir: str, connect: str | None) -> Kit:
    """Read and check KIT_DIR/join.json; TLS files are resolved against the kit directory."""
    where = os.path.join(kit_dir, "join.json")
    try:
        with open(where, encoding="utf-8") as f:
            doc = json.load(f)
    except FileNotFoundError:
        raise KitError(f"{where}: no such file (the launcher writes it last: is the run started?)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise KitError(f"{where}: {exc}") from None
    try:
        keys = {k: doc["keys"][k] for k in ("sense", "act", "tm", "isl_tx", "isl_rx")}
        timing = doc["timing"]
        zcfg = dict(doc["zenoh"])
        kit = Kit(
            path=where,
            run=doc["run"],
            spacecraft=doc["spacecraft"],
            keys=keys,
            token=doc["liveliness_token"],
            zenoh=zcfg,
            proto=os.path.join(kit_dir, doc.get("proto") or "swarmhil.proto"),
            mode=str(timing.get("mode") or "lockstep"),
            steps=int(timing["steps"]),
            decision_period_steps=max(1, int(timing.get("decision_period_steps") or 1)),
            stall_timeout_s=float((timing.get("deadline") or {}).get("stall_timeout_s") or 120.0),
            law=law_from_kit(doc["agent"], where),
        )
    except KeyError as exc:
        raise KitError(f"{where}: missing field {exc}") from None
    types = doc.get("message_types") or {}
    if types.get("sense") != "swarmhil.v1.RelStimulus":
        raise KitError(f"{where}: sense carries {types.get('sense')!r}; this computer reads swarmhil.v1.RelStimulus")
    tls = doc.get("tls")
    if tls:
        # A kit copied elsewhere: take each TLS file from its own directory (the `tls` block's
        # paths are relative to the kit), not the absolute path the launcher wrote.
        for role, zkey in TLS_KEYS.items():
            if role not in tls:
                raise KitError(f"{where}: tls has no {role!r} file")
            zcfg[zkey] = os.path.join(os.path.abspath(kit_dir), tls[role])
    for zkey in TLS_KEYS.values():
        if zkey in zcfg and not os.path.isfile(zcfg[zkey]):
            raise KitError(f"{where}: TLS file {zcfg[zkey]} ({zkey}) does not exist")
    if connect:
        zcfg["connect/endpoints"] = [connect]
    if not os.path.isfile(kit.proto):
        raise KitError(f"{where}: proto file {kit.proto} does not exist")
    return kit


def generate_messages(proto_path: str) -> tuple[Any, str]:
    """Generate the Python protobuf module from the kit's proto; returns (module, temp dir)."""
    from grpc_tools import protoc  # grpcio-tools: protoc as a library

    out = tempfile.mkdtemp(prefix="fc2-proto-")
    src_dir, name = os.path.split(os.path.abspath(proto_path))
    shutil.copy(proto_path, os.path.join(out, name))
    rc = protoc.main(["protoc", f"-I{out}", f"--python_out={out}", os.path.join(out, name)])
    if rc != 0:
        shutil.rmtree(out, ignore_errors=True)
        raise KitError(f"{proto_path}: protoc failed (exit {rc})")
    sys.path.insert(0, out)
    module = importlib.import_module(name.removesuffix(".proto") + "_pb2")
    return module, out


def zenoh_config(settings: dict[str, Any]) -> zenoh.Config:
    """A client config from the kit's ``zenoh`` block, key by key."""
    cfg = zenoh.Config()
    for key, value in settings.items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


# --------------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------------


def stamp(header: Any, kit: Kit, stimulus_header: Any, seq: int) -> None:
    """Fill an answer's header: this run and spacecraft, the stimulus's step and time, a per-key count."""
    header.run = kit.run
    header.source = kit.spacecraft
    header.step = stimulus_header.step
    header.t = stimulus_header.t
    header.seq = seq


def router_gone_for(session: zenoh.Session, since: list[float | None]) -> float:
    """Seconds this session has had no router (0 while it has one); since[0] keeps when it went."""
    if session.info.routers_zid():
        since[0] = None
        return 0.0
    if since[0] is None:
        since[0] = time.monotonic()
    return time.monotonic() - since[0]


def fly(kit: Kit, pb: Any, delay_s: float, telemetry: bool, rejoin_margin_s: float = REJOIN_MARGIN_S) -> int:
    """Join, answer every stimulus until the last step, stay until the router is gone."""
    inbox: queue.Queue[tuple[str, bytes]] = queue.Queue()
    enc = {t: zenoh.Encoding(f"application/protobuf;swarmhil.v1.{t}") for t in ("ActuatorCommand", "Telemetry")}
    session = zenoh.open(zenoh_config(kit.zenoh))
    try:
        # Subscribers first, then the token: the first stimulus follows the token at once.
        subs = [
            session.declare_subscriber(kit.keys["sense"], lambda s: inbox.put(("sense", s.payload.to_bytes()))),
            session.declare_subscriber(kit.keys["isl_rx"], lambda s: inbox.put(("isl_rx", s.payload.to_bytes()))),
        ]
        act_pub = session.declare_publisher(kit.keys["act"], encoding=enc["ActuatorCommand"])
        tm_pub = session.declare_publisher(kit.keys["tm"], encoding=enc["Telemetry"])
        token = session.liveliness().declare_token(kit.token)
        print(f"{PROG}: {kit.spacecraft} joined run {kit.run} ({kit.law.name}); waiting for stimuli", flush=True)

        seq = {"act": 0, "tm": 0}
        held = COLD  # until the first decision step: what the built-in agent answers before its first decision
        answered = 0
        last_step = -1
        last_answer = time.monotonic()
        bad = 0
        rejoin_after_s = kit.stall_timeout_s + rejoin_margin_s
        gone: list[float | None] = [None]  # since when no router has been connected
        while last_step < kit.steps - 1:
            try:
                key, payload = inbox.get(timeout=0.5)
            except queue.Empty:
                if router_gone_for(session, gone) >= ROUTER_GONE_S:
                    print(f"{PROG}: {kit.spacecraft} answered {answered} stimuli (last step {last_step} of "
                          f"{kit.steps - 1}); the run's router is gone, leaving", file=sys.stderr, flush=True)
                    return 1
                if kit.mode == "lockstep" and answered and time.monotonic() - last_answer > rejoin_after_s:
                    # Dropped without being told (the plant waits no longer than stall_timeout_s for
                    # anyone): rejoin by declaring the token again; the plant sends the next step.
                    print(f"{PROG}: no stimulus for {rejoin_after_s:g} s after step {last_step}: "
                          "dropped; declaring the token again", file=sys.stderr, flush=True)
                    token.undeclare()
                    token = session.liveliness().declare_token(kit.token)
                    held = COLD  # rejoined cold, as a restarted agent
                    last_answer = time.monotonic()
                continue
            if key != "sense":
                continue  # drift-null and null use no link packets
            t0 = time.perf_counter()
            stim = pb.RelStimulus()
            try:
                stim.ParseFromString(payload)
            except Exception as exc:  # noqa: BLE001 - any decode error: one line, skip it
                bad += 1
                print(f"{PROG}: {kit.keys['sense']}: stimulus does not decode ({exc}); ignored", file=sys.stderr)
                continue
            if stim.header.run != kit.run:
                bad += 1
                print(f"{PROG}: {kit.keys['sense']}: stimulus of run {stim.header.run!r}, not {kit.run!r}; ignored",
                      file=sys.stderr)
                continue
            k = stim.header.step
            if k % kit.decision_period_steps == 0:
                held = kit.law.decide([(nb.position_m.x, nb.velocity_mps.y) for nb in stim.neighbours])
            accel, mode = held
            if delay_s > 0.0:
                time.sleep(delay_s)
            cmd = pb.ActuatorCommand()
            stamp(cmd.header, kit, stim.header, seq["act"])
            cmd.accel_mps2.x, cmd.accel_mps2.y, cmd.accel_mps2.z = accel
            cmd.controller = kit.law.name
            cmd.isl_tx_count = 0
            act_pub.put(cmd.SerializeToString())
            seq["act"] += 1
            compute_s = time.perf_counter() - t0
            if telemetry:
                tm = pb.Telemetry()
                stamp(tm.header, kit, stim.header, seq["tm"])
                tm.mode = mode
                tm.controller = f"{kit.law.name}/fc2"  # the recording says who flew it
                tm.accel_mps2.x, tm.accel_mps2.y, tm.accel_mps2.z = accel
                tm.compute_s = compute_s
                tm.rejected_packets = bad
                tm_pub.put(tm.SerializeToString())
                seq["tm"] += 1
            answered += 1
            last_step = k
            last_answer = time.monotonic()

        # The last command is out: stay until the launcher stops the router after run_end.
        while router_gone_for(session, gone) < ROUTER_GONE_S:
            time.sleep(0.1)
        print(f"{PROG}: {kit.spacecraft} answered {answered} stimuli (last step {last_step}); "
              f"{bad} rejected; router gone, leaving", flush=True)
        del subs
        return 0
    finally:
        try:
            session.close()
        except Exception:  # noqa: BLE001 - the router is gone: closing may time out
            pass


def main(argv: list[str] | None = None) -> int:
    """Command line: fc2.py KIT_DIR [--connect ENDPOINT] [--delay-s S] [--no-telemetry] [--rejoin-margin-s S]."""
    ap = argparse.ArgumentParser(prog="fc2.py", description="A second external flight computer (drift-null, null).")
    ap.add_argument("kit", help="the join kit directory the launcher wrote (DIR/external/<id>)")
    ap.add_argument("--connect", help="connect here instead of the kit's router endpoint (e.g. an SSH tunnel)")
    ap.add_argument("--delay-s", type=float, default=0.0, help="sleep this long before each command (a slow computer)")
    ap.add_argument("--no-telemetry", action="store_true", help="publish no Telemetry")
    ap.add_argument("--rejoin-margin-s", type=float, default=REJOIN_MARGIN_S,
                    help="lockstep: declare the token again after stall_timeout_s + this without a stimulus")
    args = ap.parse_args(argv)
    out = None
    try:
        kit = load_kit(args.kit, args.connect)
        pb, out = generate_messages(kit.proto)
        return fly(kit, pb, args.delay_s, not args.no_telemetry, args.rejoin_margin_s)
    except KitError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    except zenoh.ZError as exc:
        print(f"{PROG}: cannot join: {str(exc).splitlines()[0] if str(exc) else exc!r}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        if out:
            shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
