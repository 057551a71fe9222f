"""Zenoh sessions and the Zenoh implementation of the bus interface (bus/base.py).

Network rule: every session listens and connects only on the explicit endpoints it is given
(loopback by default), with multicast and gossip scouting off. This module is the one place a
Zenoh config is built.
"""
from __future__ import annotations

import ctypes
import json
import logging
import queue
import socket
import threading
from collections.abc import Sequence
from typing import Any

import zenoh

from swarmhil.bus.base import LivelinessCallback, SampleCallback

log = logging.getLogger("swarmhil.zenoh")

LOOPBACK = "127.0.0.1"


_pinned = threading.local()
_gil_state_ensure = ctypes.pythonapi.PyGILState_Ensure


def _pin_thread_state() -> None:
    """Keep this (Zenoh network) thread's Python thread state for the life of the thread.

    zenoh-python runs an `indirect=False` callback on a Rust thread that Python does not know:
    each call takes the GIL with PyGILState_Ensure, which creates a thread state (and maps its
    frame stack) and deletes it again on return. Measured (issue 16, one subscriber, 160 B
    samples): 16-20 us of CPU per received sample that way, 6-7 us with the thread state kept,
    which one extra, never released PyGILState_Ensure does (the call here runs with the GIL and
    the thread state current, so it only counts up). Idempotent per thread; the thread states
    are released with the process. Callbacks stop before the interpreter finalises: every process
    closes its session first (deploy/proc.py)."""
    if not getattr(_pinned, "done", False):
        _gil_state_ensure()
        _pinned.done = True


def free_loopback_port() -> int:
    """A TCP port free on 127.0.0.1 now (the OS picks it, so two runs can coexist).

    Free *now*: the socket is closed before the caller binds it, so another process can take the
    port in between. A listener should bind through `open_loopback_router`, which retries."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def endpoint(port: int, host: str = LOOPBACK, proto: str = "tcp") -> str:
    return f"{proto}/{host}:{port}"


def zenoh_config(mode: str, listen: list[str], connect: list[str], overrides: dict[str, Any] | None = None) -> zenoh.Config:
    """Config with explicit endpoints and no scouting (STACK-NOTES: defaults listen on every interface)."""
    for ep in listen + connect:
        if "0.0.0.0" in ep or "[::]" in ep:
            raise ValueError(f"endpoint {ep!r} is a wildcard address; give an explicit one")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("listen/endpoints", json.dumps(listen))
    cfg.insert_json5("connect/endpoints", json.dumps(connect))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    for key, value in (overrides or {}).items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


def open_router(listen: str, overrides: dict[str, Any] | None = None, also: Sequence[str] = (),
                connect: Sequence[str] = ()) -> zenoh.Session:
    """A Python session in router mode: the run's router (no zenohd binary needed).

    `overrides` carries the run's authentication dictionary and access control (bus/acl.py); `also`:
    more endpoints to listen on (external flight software on another host, deploy/external.py);
    `connect`: other routers of the run to link to (a mesh of routers, deploy/mesh.py), which a
    router keeps retrying in the background until they answer."""
    return zenoh.open(zenoh_config("router", [listen, *also], list(connect), overrides))


def _address_in_use(exc: BaseException) -> bool:
    text = str(exc)
    return "Address already in use" in text or "os error 98" in text or "AddrInUse" in text


def open_loopback_router(attempts: int = 8, port_source=None,
                         overrides: dict[str, Any] | None = None, proto: str = "tcp") -> tuple[zenoh.Session, str]:
    """A router listening on a free 127.0.0.1 port: (session, endpoint).

    The port comes from `free_loopback_port` (or `port_source`, for tests) and is closed before
    Zenoh binds it, so another process may take it in between; when zenoh.open fails with
    "address already in use" a new port is drawn, up to `attempts` times. Any other error, or
    the last collision, is raised. `overrides`: as for open_router; `proto` "tls" with the run's
    certificates in the overrides (bus/tls.py)."""
    pick = port_source or free_loopback_port
    for attempt in range(1, attempts + 1):
        ep = endpoint(pick(), proto=proto)
        try:
            return open_router(ep, overrides), ep
        except zenoh.ZError as exc:
            if not _address_in_use(exc) or attempt == attempts:
                raise
            log.warning("router port %s was taken before Zenoh bound it (attempt %d of %d); trying another",
                        ep, attempt, attempts)
    raise AssertionError("unreachable")


# A client whose router refuses it (no or wrong credentials) would otherwise retry for ever.
CONNECT_TIMEOUT_MS = 15000


def open_client(connect: str, overrides: dict[str, Any] | None = None, credential: Any = None) -> zenoh.Session:
    """A client session; `credential` (bus.acl.Credential) authenticates it to the run's router."""
    ov = {"connect/timeout_ms": CONNECT_TIMEOUT_MS, **(overrides or {})}
    if credential is not None:
        ov.update(credential.zenoh_overrides())
    return zenoh.open(zenoh_config("client", [], [connect], ov))


class ZenohBus:
    """Bus over a Zenoh client session.

    Zenoh delivers samples on its own threads; the callbacks here only enqueue, and one
    dispatcher thread runs the node callbacks in arrival order (STACK-NOTES: a slow callback
    delays every other subscriber of the session).

    Order across keys (issue 10): zenoh-python runs a plain Python callable on a separate thread
    per subscriber (`zenoh.handlers.Callback(..., indirect=True)`, the default), so two samples
    published in order on two keys by one session could reach the dispatcher queue in the other
    order (an agent's `isl/tx` packet after its `act` command: the link channel then closed the
    window without it). The enqueue callbacks here are declared `indirect=False`: they run on
    the network thread that received the samples, in the order the link delivered them, and do
    nothing but a queue put, so they never block that thread.

    `direct=True` (issue 16, the lockstep's critical path): the node callbacks run on that network
    thread themselves, in the same arrival order, without the hop through the queue and the
    dispatcher thread (a wake-up and a GIL hand-over per sample). For a process whose callbacks are
    its whole work and short (an agent: one stimulus in, its command and telemetry out; the
    plant's commands): a slow callback there only delays that process's own next samples. Not
    for the recorder (its writes would back-pressure the router).
    """

    def __init__(self, connect: str, *, lease_ms: int | None = None, credential: Any = None,
                 direct: bool = False) -> None:
        overrides = {"transport/link/tx/lease": lease_ms} if lease_ms else None
        self.session = open_client(connect, overrides, credential)
        self.direct = direct
        self._queue: queue.SimpleQueue[tuple[Any, ...] | None] = queue.SimpleQueue()
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._handles: list[Any] = []
        self._closed = False
        self._thread = threading.Thread(target=self._dispatch, name="bus-dispatch", daemon=True)
        self._thread.start()

    def _dispatch(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            fn, *args = item
            try:
                fn(*args)
            except Exception:  # a node bug must not kill the dispatcher silently
                log.exception("callback %r failed", fn)

    def publish(self, key: str, payload: bytes) -> None:
        pub = self._publishers.get(key)
        if pub is None:
            from swarmhil.bus.codec import encoding_of_key  # here: a router process needs no numpy/protobuf

            enc = encoding_of_key(key)  # typed live traffic: application/protobuf;<message type>
            pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                                 encoding=zenoh.Encoding(enc) if enc else None)
            self._publishers[key] = pub
        pub.put(payload)

    @property
    def _deliver(self) -> Any:
        """Where a sample's callback runs: here on the network thread (`direct`), or on the
        dispatcher thread through the queue (chosen once per subscription)."""
        if self.direct:
            return self._run_direct
        q = self._queue
        return lambda fn, *args: q.put((fn, *args))

    def _run_direct(self, fn: Any, *args: Any) -> None:
        try:
            fn(*args)
        except Exception:  # as in the dispatcher: a node bug must not kill the network thread's callback
            log.exception("callback %r failed", fn)

    def subscribe(self, key_expr: str, callback: SampleCallback) -> Any:
        deliver = self._deliver

        def on_sample(sample: zenoh.Sample) -> None:
            _pin_thread_state()
            deliver(callback, str(sample.key_expr), sample.payload.to_bytes())

        sub = self.session.declare_subscriber(key_expr, zenoh.handlers.Callback(on_sample, indirect=False))
        self._handles.append(sub)
        return sub

    def declare_liveliness(self, key: str) -> Any:
        tok = self.session.liveliness().declare_token(key)
        self._handles.append(tok)
        return tok

    def watch_liveliness(self, key_expr: str, callback: LivelinessCallback) -> Any:
        deliver = self._deliver

        def on_change(sample: zenoh.Sample) -> None:
            _pin_thread_state()
            deliver(callback, str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        sub = self.session.liveliness().declare_subscriber(key_expr, zenoh.handlers.Callback(on_change, indirect=False),
                                                           history=True)
        self._handles.append(sub)
        return sub

    def call_soon(self, fn: Any, *args: Any) -> None:
        """Run fn(*args) on the dispatcher thread, after what is already queued."""
        self._queue.put((fn, *args))

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until every callback queued so far has run."""
        done = threading.Event()
        self._queue.put((done.set,))
        return done.wait(timeout_s)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for h in self._handles:
            try:
                h.undeclare()
            except Exception:
                pass
        for p in self._publishers.values():
            try:
                p.undeclare()
            except Exception:
                pass
        self._queue.put(None)
        self._thread.join(timeout=5)
        try:
            self.session.close()
        except Exception as exc:  # STACK-NOTES: close can time out when a peer is frozen
            log.warning("zenoh session close: %s", exc)
