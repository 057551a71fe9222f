"""`swarmhil run ... --viz foxglove` (issue 18): a live run served over Foxglove's WebSocket protocol.

A plain client (the `websockets` package, nothing of the project) connects to 127.0.0.1 with the
Foxglove WebSocket subprotocol (`foxglove-sdk` 0.30 names it `foxglove.sdk.v1`: the messages of
`foxglove.websocket.v1` under a new name; the server refuses a handshake offering only the old
name, so the client offers both), reads the server's `advertise`, subscribes to the scene,
transforms and truth channels, and decodes the binary message-data frames two ways: with the
FileDescriptorSet the server advertised (protobuf's own message factory) and with
foxglove-schemas-protobuf. The run is multi-process over Zenoh, paced in real time so it lasts
long enough to watch.
"""
from __future__ import annotations

import asyncio
import base64
import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from conftest import sigint_default

ROOT = Path(__file__).resolve().parent.parent
EPOCH_NS = 946728000 * 10**9   # demo.toml: the default [run].epoch_utc 2000-01-01T12:00:00Z
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
WANT = {"foxglove/tf": "foxglove.FrameTransforms", "foxglove/scene": "foxglove.SceneUpdate", "truth": "swarmhil.v1.Truth"}


def advertised_class(ch: dict[str, Any]) -> Any:
    """The message class of an advertised protobuf channel, built from its FileDescriptorSet alone."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))


async def watch(url: str, deadline: float, proc: subprocess.Popen, need: int = 5) -> dict[str, list[tuple[int, bytes, Any]]]:
    """Connect (retrying until the server listens), subscribe to WANT, collect `need` messages of each."""
    import websockets

    while True:
        assert proc.poll() is None, f"the run exited ({proc.returncode}) before its Foxglove server answered"
        assert time.monotonic() < deadline, f"no Foxglove server at {url}"
        try:
            ws = await websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None, open_timeout=5)
            break
        except OSError:
            await asyncio.sleep(0.2)
    got: dict[str, list[tuple[int, bytes, Any]]] = {t: [] for t in WANT}
    subs: dict[int, tuple[str, Any]] = {}
    async with ws:
        assert ws.subprotocol in SUBPROTOCOLS
        while any(len(v) < need for v in got.values()):
            assert time.monotonic() < deadline, f"messages so far: { {t: len(v) for t, v in got.items()} }"
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=max(1.0, deadline - time.monotonic()))
            except websockets.ConnectionClosed as e:  # the run ended (the server does not keep history)
                raise AssertionError(f"the server closed ({e}) with messages so far "
                                     f"{ {t: len(v) for t, v in got.items()} }, subscribed {sorted(t for t, _ in subs.values())}")
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        if ch["topic"] in WANT and ch["encoding"] == "protobuf":
                            assert ch["schemaName"] == WANT[ch["topic"]] and ch["schemaEncoding"] == "protobuf"
                            sid = len(subs) + 1
                            subs[sid] = (ch["topic"], advertised_class(ch))
                            new.append({"id": sid, "channelId": ch["id"]})
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            assert frame[0] == 0x01, f"binary opcode {frame[0]}"   # message data
            sid, log_time = struct.unpack_from("<IQ", frame, 1)
            topic, cls = subs[sid]
            got[topic].append((log_time, bytes(frame[13:]), cls.FromString(bytes(frame[13:]))))
    return got


@pytest.mark.timeout(600)
def test_live_run_serves_scene_transforms_and_truth(tmp_path: Path) -> None:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from swarmhil.bus.zenoh_bus import free_loopback_port

    port = free_loopback_port()
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(ROOT / "deploy" / "scenarios" / "demo.toml"), "--viz", "foxglove",
           "--viz-port", str(port), "--mode", "realtime", "--speed", "40", "--duration", "800", "--out", str(tmp_path / "run"),
           "--no-progress"]
    log_path = tmp_path / "cli.log"   # a file, not a pipe nobody reads while the client watches
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                preexec_fn=sigint_default)
        try:
            try:
                got = asyncio.run(watch(f"ws://127.0.0.1:{port}", time.monotonic() + 240, proc))
            except AssertionError as e:  # with what the run said (start-up, misses, the viewer's counts)
                raise AssertionError(f"{e}\n--- the run's output:\n{log_path.read_text(errors='replace')[-4000:]}") from None
            proc.wait(240)
        finally:
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGINT)   # by PID: the run started here
                proc.wait(60)
    assert proc.returncode == 0, log_path.read_text(errors="replace")
    truth_t = {lt: msg for lt, _raw, msg in got["truth"]}
    ids = None
    for lt, raw, generic in got["foxglove/tf"]:
        tf = FrameTransforms.FromString(raw)                       # the Foxglove schemas decode it too
        assert tf == FrameTransforms.FromString(generic.SerializeToString())
        frames = {x.child_frame_id: x for x in tf.transforms}
        assert {x.parent_frame_id for x in tf.transforms} == {"lvlh"}
        assert all(x.timestamp.seconds * 10**9 + x.timestamp.nanos == lt for x in tf.transforms)
        ids = ids or sorted(frames)
        assert sorted(frames) == ids and len(ids) == 6             # demo: six spacecraft
        if lt in truth_t:                                          # same log time as its truth: epoch + t
            tr = truth_t[lt]
            assert lt == EPOCH_NS + round(tr.header.t * 1e9)
            for b in tr.bodies:
                x = frames[b.id].translation
                assert (x.x, x.y, x.z) == (b.position_m.x, b.position_m.y, b.position_m.z)
    assert set(truth_t) & {lt for lt, *_ in got["foxglove/tf"]}, "no transforms at a truth's time"
    for _lt, raw, _generic in got["foxglove/scene"]:
        ents = {e.id: e for e in SceneUpdate.FromString(raw).entities}
        assert set(ids) <= set(ents) and "links" in ents
        assert all(ents[i].frame_id == i and ents[i].spheres for i in ids)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["viz"]["mode"] == "foxglove" and summary["viz"]["port"] == port
    assert summary["viz"]["samples"]["foxglove/tf"] == summary["viz"]["samples"]["truth"] > 0


def test_busy_port_is_one_line_and_exit_2(tmp_path: Path) -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(ROOT / "deploy" / "scenarios" / "demo.toml"),
                            "--viz", "foxglove", "--viz-port", str(port), "--out", str(tmp_path / "x")],
                           cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr and f"127.0.0.1:{port}" in r.stderr
