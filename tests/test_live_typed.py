"""Typed live traffic (DESIGN.md "MCAP (contract)", issue 18): a plain client decodes every live key.

The client here imports nothing of the project: its own zenoh session (client mode, loopback,
scouting off) on the router of a multi-process run started as a subprocess (`python -m
deploy.cli run`), protobuf classes built from bus/swarmhil.proto (protoc -> FileDescriptorSet ->
descriptor pool), and bus/keys.json for the key -> type map. Every sample must carry the encoding
`application/protobuf;<type>` where <type> is what keys.json says, and parse as that type.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, sigint_default

RUN = "live-typed"


def _classes(tmp: Path) -> dict[str, type]:
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    out = tmp / "swarmhil.desc"
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", "-I", str(ROOT / "bus"), f"--descriptor_set_out={out}",
                    "--include_imports", str(ROOT / "bus" / "swarmhil.proto")], check=True)
    fds = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes())
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    classes = {}
    for fd in fds.file:
        for m in fd.message_type:
            name = f"{fd.package}.{m.name}" if fd.package else m.name
            classes[name] = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
    return classes


def _type_of(keys_json: dict, key: str, run: str = RUN) -> str | None:
    prefix = f"swarm/{run}/"
    assert key.startswith(prefix), key
    parts = key[len(prefix):].split("/")
    for entry in keys_json["keys"]:
        pat = entry["key"].split("/")
        if len(pat) == len(parts) and all(p == "*" or p == k for p, k in zip(pat, parts)):
            return entry["type"]
    raise AssertionError(f"{key} matches no entry of bus/keys.json")


def _plain_session(router: str):
    import zenoh

    cfg = zenoh.Config()
    for k, v in {"mode": "client", "connect/endpoints": [router], "listen/endpoints": [],
                 "scouting/multicast/enabled": False, "scouting/gossip/enabled": False}.items():
        cfg.insert_json5(k, json.dumps(v))
    assert router.startswith("tcp/127.0.0.1:"), router
    return zenoh.open(cfg)


def _wait_router(path: Path, proc: subprocess.Popen, timeout_s: float = 60.0) -> str:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if path.is_file():
            try:
                return json.loads(path.read_text())["router"]
            except (ValueError, KeyError):
                pass
        assert proc.poll() is None, "the run ended before its router was known"
        time.sleep(0.02)
    raise TimeoutError(path)


def test_plain_client_decodes_every_live_key(tmp_path: Path) -> None:
    keys_json = json.loads((ROOT / "bus" / "keys.json").read_text())
    classes = _classes(tmp_path)
    out = tmp_path / "run"
    # four agents, the link channel and beacons: every kind of key the stack publishes
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(SCENARIOS / "sabatini-20-beacon.toml"), "--out", str(out),
           "--run-id", RUN, "--no-progress", "--duration", "400", "--mode", "realtime", "--speed", "80",
           "--set", "dispersion.count=4", "--set", "dispersion.require_weakly_connected=false",
           "--insecure"]  # the plain client has no credentials: an open router (the ACL: tests/test_security.py)
    proc = subprocess.Popen(cmd, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, preexec_fn=sigint_default)
    seen: list[tuple[str, str, bytes]] = []
    lock = threading.Lock()
    session = None
    try:
        router = _wait_router(out / "run.json", proc)
        session = _plain_session(router)

        def on_sample(sample) -> None:  # type: ignore[no-untyped-def]
            with lock:
                seen.append((str(sample.key_expr), str(sample.encoding), sample.payload.to_bytes()))

        session.declare_subscriber(f"swarm/{RUN}/**", on_sample)
        log, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, log
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if session is not None:
            session.close()
    with lock:
        samples = list(seen)
    assert len(samples) > 100
    keys = {k for k, _e, _p in samples}
    rels = [k.split("/")[2:] for k in keys]
    kinds = {f"sc/{r[2]}" if r[0] == "sc" else "/".join(r[:2]) if r[0] in ("isl", "link") else r[0] for r in rels}
    # (alive/* are liveliness tokens, not publications)
    for want in ("clock", "truth", "event", "link/stats", "sc/sense", "sc/act", "sc/tm", "isl/tx", "isl/rx", "sync"):
        assert want in kinds, (want, sorted(kinds))
    for key, encoding, payload in samples:
        type_name = _type_of(keys_json, key)
        assert encoding == f"application/protobuf;{type_name}", (key, encoding)
        msg = classes[type_name].FromString(payload)
        if "header" in msg.DESCRIPTOR.fields_by_name and msg.HasField("header"):
            assert msg.header.run == RUN, key
    # every key the recording holds was also decoded live (the recorder sees what the client sees)
    from mcap.reader import make_reader

    with open(out / "run.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    recorded = {ch.topic for ch in summary.channels.values() if not ch.topic.startswith("foxglove/")}
    live = {k[len(f"swarm/{RUN}/"):] for k in keys}
    assert recorded <= live, sorted(recorded - live)


@pytest.mark.parametrize("example,expected", [
    ("swarm/r/truth", "swarmhil.v1.Truth"), ("swarm/r/sc/a/sense/rel", "swarmhil.v1.RelStimulus"),
    ("swarm/r/sc/a/sense/lidar", "swarmhil.v1.Measurements"), ("swarm/r/sc/a/tm/image", "foxglove.CompressedImage"),
    ("swarm/r/isl/rx/b", "swarmhil.v1.IslPacket"), ("swarm/r/sync/channel", "swarmhil.v1.Tick"),
])
def test_keys_json_lookup(example: str, expected: str) -> None:
    keys_json = json.loads((ROOT / "bus" / "keys.json").read_text())
    assert _type_of(keys_json, example, run="r") == expected
