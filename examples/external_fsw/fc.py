#!/usr/bin/env python3
"""A reference external flight computer for swarmhil (docs/hil.md).

It imports nothing of the swarmhil project: only eclipse-zenoh, numpy and the protobuf code that
./build.sh generates from the run's swarmhil.proto. Everything else it learns from the join kit
that `swarmhil run` writes for a spacecraft with `fsw = "external"` (DIR/external/<id>/join.json).

    ./build.sh KIT/swarmhil.proto build     # once: build/swarmhil_pb2.py
    python fc.py KIT                        # joins the run, flies the spacecraft until the run ends

Its law is the drift-null controller (the built-in `drift-null` of swarmhil, the same arithmetic in
the same order, so the truth of a lockstep run is bit-identical to the built-in one's): along-track
thrust that cancels the mean relative drift to the visible neighbours,

    a*da_k = 4 x_k + 2 vy_k / n          (relative semi-major axis of neighbour k)
    u_y    = clip(gain * n / 2 * mean_k(a*da_k), -max_accel, max_accel)

Per step: a stimulus arrives on keys.sense with header.step = k; the answer is one
ActuatorCommand on keys.act with the same run, step and t, source = the spacecraft id, before the
plant's deadline (join.json "timing"). It leaves when the run's router goes away, or on SIGTERM.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

ROUTER_GONE_S = 2.0  # the run is over once the router has been gone this long


def load_kit(kit: Path) -> dict[str, Any]:
    doc = json.loads((kit / "join.json").read_text())
    if doc.get("kit_version") != 1:
        raise SystemExit(f"fc: {kit}/join.json: kit_version {doc.get('kit_version')!r}, this computer speaks 1")
    return doc


TLS_ROLES = {"transport/link/tls/root_ca_certificate": "ca", "transport/link/tls/connect_certificate": "cert",
             "transport/link/tls/connect_private_key": "key"}


def zenoh_config(kit: Path, doc: dict[str, Any], connect: str | None) -> zenoh.Config:
    """The kit's client settings. The TLS files are taken from the kit's `tls` names, relative to
    the kit directory (so a kit copied to another machine works too), and checked before dialling:
    Zenoh reads them only when it connects, and a missing one shows up as a bare connect timeout."""
    cfg = zenoh.Config()
    for key, value in doc["zenoh"].items():
        if key in TLS_ROLES:
            value = str((kit / doc["tls"][TLS_ROLES[key]]).resolve())
            if not Path(value).is_file():
                raise SystemExit(f"fc: {kit}/join.json: TLS file {value} ({key}) does not exist")
        if key == "connect/endpoints" and connect:
            value = [connect]
        cfg.insert_json5(key, json.dumps(value))
    return cfg


def drift_null(rel_pos_m: np.ndarray, rel_vel_mps: np.ndarray, n_radps: float, gain_per_s: float,
               max_accel_mps2: float) -> tuple[np.ndarray, str]:
    """The along-track command of the drift-null law (module docstring) and the mode."""
    if len(rel_pos_m) == 0:
        return np.zeros(3), "search"
    da_m = 4.0 * rel_pos_m[:, 0] + 2.0 * rel_vel_mps[:, 1] / n_radps
    uy = gain_per_s * n_radps / 2.0 * float(np.mean(da_m))
    uy = float(np.clip(uy, -max_accel_mps2, max_accel_mps2))
    return np.array([0.0, uy, 0.0]), "drift-null"


class FlightComputer:
    """Stimulus in, command (and telemetry) out, on Zenoh's callback thread: one step is a few
    microseconds of numpy."""

    def __init__(self, session: zenoh.Session, doc: dict[str, Any], pb: Any, print_steps: bool,
                 delay_s: float = 0.0) -> None:
        self.pb = pb
        self.doc = doc
        self.run, self.id = doc["run"], doc["spacecraft"]
        agent = doc["agent"]
        self.n = float(agent["orbit"]["mean_motion_radps"])
        self.gain = float(agent["params"].get("gain_per_s", 1e-4))
        self.max_accel = float(agent["params"].get("max_accel_mps2", 1e-3))
        self.period = int(doc["timing"]["decision_period_steps"])
        self.name = "drift-null"  # the law's name in its commands (swarmhil refly compares it with the built-in's)
        self.who = "drift-null/external"  # in its telemetry: the recording says who flew it
        self.accel, self.mode = np.zeros(3), "init"
        self.seq = {"act": 0, "tm": 0}
        self.steps = 0
        self.print_steps = print_steps
        self.delay_s = delay_s  # a slower computer: seconds added to every step's compute
        keys, types = doc["keys"], doc["message_types"]
        self.stim_cls = getattr(pb, types["sense"].rsplit(".", 1)[-1])
        self.act = session.declare_publisher(keys["act"], encoding=zenoh.Encoding(f"application/protobuf;{types['act']}"))
        self.tm = session.declare_publisher(keys["tm"], encoding=zenoh.Encoding(f"application/protobuf;{types['tm']}"))
        # the subscriber before the token: the plant sends this step's stimulus as soon as it sees
        # the token (at the start, and on a rejoin); one sent before the subscriber is up is lost
        self.sub = session.declare_subscriber(keys["sense"], self.on_stimulus)
        self.token = session.liveliness().declare_token(keys["alive"])

    def header(self, key: str, step: int, t: float) -> Any:
        seq = self.seq[key]
        self.seq[key] = seq + 1
        return self.pb.Header(run=self.run, source=self.id, step=step, t=t, seq=seq)

    def on_stimulus(self, sample: zenoh.Sample) -> None:
        t0 = time.perf_counter()
        stim = self.stim_cls.FromString(sample.payload.to_bytes())
        if stim.header.run != self.run:
            return  # not this run's: never act on it
        step, t = int(stim.header.step), stim.header.t
        if step % self.period == 0:
            nbs = stim.neighbours
            pos = np.array([(p.x, p.y, p.z) for p in (nb.position_m for nb in nbs)], dtype=float).reshape(-1, 3)
            vel = np.array([(v.x, v.y, v.z) for v in (nb.velocity_mps for nb in nbs)], dtype=float).reshape(-1, 3)
            self.accel, self.mode = drift_null(pos, vel, self.n, self.gain, self.max_accel)
        if self.delay_s:
            time.sleep(self.delay_s)
        compute_s = time.perf_counter() - t0
        ax, ay, az = self.accel.tolist()
        cmd = self.pb.ActuatorCommand(header=self.header("act", step, t), controller=self.name, isl_tx_count=0,
                                      accel_mps2=self.pb.Vector3(x=ax, y=ay, z=az))
        self.act.put(cmd.SerializeToString())
        tm = self.pb.Telemetry(header=self.header("tm", step, t), mode=self.mode, controller=self.who,
                               accel_mps2=self.pb.Vector3(x=ax, y=ay, z=az), compute_s=compute_s)
        self.tm.put(tm.SerializeToString())
        self.steps += 1
        if self.print_steps:
            print(f"step {step} accel_y {ay:.6e}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="fc.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("kit", type=Path, help="the join kit directory (DIR/external/<id>)")
    ap.add_argument("--build", type=Path, default=Path(__file__).resolve().parent / "build",
                    help="where build.sh wrote swarmhil_pb2.py (default: ./build beside this file)")
    ap.add_argument("--connect", help="another router endpoint than the kit's (e.g. an ssh-forwarded port)")
    ap.add_argument("--print-steps", action="store_true", help="one line per step answered")
    ap.add_argument("--audit", type=Path, help="write the top-level modules this process imported to this file")
    ap.add_argument("--delay-s", type=float, default=0.0, help="emulate a slower computer: sleep this long per step")
    args = ap.parse_args(argv)
    doc = load_kit(args.kit)
    if doc["message_types"]["sense"] not in ("swarmhil.v1.RelStimulus", "swarmhil.v1.Measurements"):
        print(f"fc: this computer flies on neighbours' relative states (RelStimulus, Measurements), not on "
              f"{doc['message_types']['sense']}", file=sys.stderr, flush=True)
        return 2
    sys.path.insert(0, str(args.build.resolve()))
    pb = importlib.import_module("swarmhil_pb2")
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    try:
        session = zenoh.open(zenoh_config(args.kit, doc, args.connect))
    except zenoh.ZError as exc:
        where = args.connect or doc["router"]
        print(f"fc: cannot join run {doc['run']} at {where}: {exc}", file=sys.stderr, flush=True)
        return 1
    fc = FlightComputer(session, doc, pb, args.print_steps, args.delay_s)
    print(f"fc: flying {doc['spacecraft']} of run {doc['run']} ({doc['timing']['mode']}, "
          f"{doc['timing']['step_s']} s steps)", flush=True)
    gone_since = None
    while not stop.wait(0.2):
        if list(session.info.routers_zid()):
            gone_since = None
        elif gone_since is None:
            gone_since = time.monotonic()
        elif time.monotonic() - gone_since > ROUTER_GONE_S:
            break  # the run is over (its router stopped)
    print(f"fc: answered {fc.steps} stimuli", flush=True)
    if args.audit:
        args.audit.write_text(json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
    fc.token.undeclare()
    closing = threading.Thread(target=session.close, daemon=True)  # a close can hang when the router is gone
    closing.start()
    closing.join(2.0)
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)  # no interpreter teardown with Zenoh's threads still up
