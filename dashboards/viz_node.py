"""The viewer bridge companion "viz" (deploy/companions.py): the run's samples -> Rerun (or Foxglove).

Subscribes to truth, telemetry (and camera frames), events, link statistics and ISL deliveries,
and for paper 000 the sensing stimuli that carry landmark returns (over Zenoh: ring-channel subscribers drained every DRAIN_PERIOD_S, so no Python runs on Zenoh's
threads); the samples are only queued (dashboards/rerun_bridge.py), and a timer flushes them in
column batches every FLUSH_PERIOD_S (0.5 s live, 2 s when only saving), so the bridge costs little
and the plant never waits for it (LOCKSTEP_BARRIER = False: not a lockstep participant). When only
saving, as its own process, it lowers its scheduling priority (nice NICE), so on a busy machine the
run goes first and the bridge catches up in the gaps of the lockstep exchange.

Modes (opts["viz"]):
    save     RUN_DIR/run.rrd (FileSink)
    serve    gRPC server sink on 127.0.0.1:opts["viz_port"] plus the web viewer of the wheel
             (`rerun --serve-web --bind 127.0.0.1 ...`, a child process ended by PID) on
             127.0.0.1:opts["web_port"]; also writes RUN_DIR/run.rrd. The URL goes to the log,
             RUN_DIR/viewer_url.txt and the summary.
    connect  stream to a running viewer at opts["viz_url"] (default rerun+http://127.0.0.1:9876/proxy);
             also writes RUN_DIR/run.rrd.
    foxglove a Foxglove WebSocket server on 127.0.0.1:opts["viz_port"] (default 8765) sending the
             run as its recording holds it (dashboards/foxglove_live.py); no Rerun, no .rrd.
Rerun servers bind 127.0.0.1 only (STACK-NOTES: rr.serve_grpc / serve_web_viewer bind 0.0.0.0).
Rerun is imported only when a bridge starts: the launcher imports this module for every run.
"""
from __future__ import annotations

import logging
import os
import resource
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any
from urllib.parse import quote

from swarmhil.bus.keys import Keys
from swarmhil.bus.optional import require
from swarmhil.bus.zenoh_bus import free_loopback_port
from swarmhil.dashboards.foxglove_live import DEFAULT_PORT, FoxgloveLive

log = logging.getLogger("swarmhil.viz")

LOCKSTEP_BARRIER = False
MODES = ("save", "serve", "connect", "foxglove")
LOOPBACK = "127.0.0.1"
DEFAULT_CONNECT_URL = "rerun+http://127.0.0.1:9876/proxy"
FLUSH_PERIOD_S = {"save": 2.0, "serve": 0.5, "connect": 0.5, "foxglove": 0.5}   # batch more when nobody watches live
DRAIN_PERIOD_S = 0.1
RING_CAPACITY = 1 << 17   # samples per subscription held by Zenoh between drains (the oldest go first if full)
NICE = 10   # as its own process the bridge yields the CPU to the plant and agents, and catches up in their gaps

_analytics_done = False


def enabled(sc: Any, opts: dict[str, Any]) -> bool:
    return opts.get("viz") in MODES


def start(bus: Any, run: str, sc: Any, out: Path, opts: dict[str, Any]) -> "VizNode":
    return VizNode(bus, run, sc, Path(out), opts)


def rerun_exe() -> str:
    """The rerun binary of the wheel (package rerun_cli), else the `rerun` on PATH.

    The binary itself, not the venv's `bin/rerun` Python wrapper: the wrapper runs the binary as a
    child, so ending the wrapper by PID would leave the server running.
    """
    try:
        import rerun_cli

        exe = Path(rerun_cli.__file__).with_name("rerun")
        if exe.exists():
            return str(exe)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if not found:
        raise FileNotFoundError("the rerun CLI (rerun-sdk wheel) is not installed")
    return found


def _die_with_parent() -> None:
    """Child pre-exec: SIGTERM when the process that started it dies (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)
    except OSError:
        pass


def disable_analytics() -> None:
    """`rerun analytics disable` once per process, before anything starts the CLI or a viewer."""
    global _analytics_done
    if _analytics_done:
        return
    try:
        subprocess.run([rerun_exe(), "analytics", "disable"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        log.warning("rerun analytics disable failed: %s", exc)
    _analytics_done = True


def grpc_url(port: int) -> str:
    return f"rerun+http://{LOOPBACK}:{port}/proxy"


def web_url(web_port: int, grpc_port: int) -> str:
    """The page to open, in the form `rerun --serve-web` prints (every character of the data URL escaped)."""
    return f"http://{LOOPBACK}:{web_port}?url={quote(grpc_url(grpc_port), safe='').replace('.', '%2E')}"


def free_port() -> int:
    return free_loopback_port()


def ring_subscriber(session: Any, key_expr: str) -> Any:
    """A Zenoh subscriber whose samples wait in a ring channel until drained.

    No Python callback runs on Zenoh's threads, so a busy bridge (holding the GIL while it logs)
    never stalls its session, and so never pushes back on the router and the run's publishers
    (STACK-NOTES: BLOCK congestion control and a slow subscriber block the publisher; a ring
    channel never does).
    """
    import zenoh

    return session.declare_subscriber(key_expr, zenoh.handlers.RingChannel(RING_CAPACITY))


class WebViewer:
    """`rerun --serve-web` serving the wheel's web viewer on 127.0.0.1, pointed at a gRPC proxy URL."""

    def __init__(self, web_port: int, grpc_port: int, log_path: Path | None = None) -> None:
        disable_analytics()
        self.url = web_url(web_port, grpc_port)
        cmd = [rerun_exe(), "--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(web_port), grpc_url(grpc_port)]
        self._logf = open(log_path, "wb") if log_path else subprocess.DEVNULL
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=self._logf, stderr=subprocess.STDOUT,
                                     preexec_fn=_die_with_parent if sys.platform == "linux" else None)

    def wait_listening(self, port: int, timeout_s: float = 20.0) -> bool:
        import socket

        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end and self.proc.poll() is None:
            with socket.socket() as s:
                if s.connect_ex((LOOPBACK, port)) == 0:
                    return True
            time.sleep(0.1)
        return False

    def close(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGTERM)  # by PID: the child this object started
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        if self._logf is not subprocess.DEVNULL:
            self._logf.close()


def open_recording(run: str, recording_id: str, *, mode: str, rrd: Path | None, viz_port: int | None = None,
                   viz_url: str | None = None) -> Any:
    """A RecordingStream with the sinks of a mode (rrd: also write this file)."""
    from swarmhil.dashboards.rerun_bridge import APP_ID  # viewer extra: rerun_bridge imports rerun

    rr = require("rerun", "the Rerun viewer (--viz)")

    rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
    sinks: list[Any] = []
    if mode == "serve":
        sinks.append(rr.GrpcServerSink(bind_ip=LOOPBACK, port=int(viz_port or 0), newest_first=True))
    elif mode == "connect":
        sinks.append(rr.GrpcSink(viz_url or DEFAULT_CONNECT_URL))
    if rrd is not None:
        sinks.append(rr.FileSink(str(rrd)))
    rec.set_sinks(*sinks)
    return rec


class VizNode:
    def __init__(self, bus: Any, run: str, sc: Any, out: Path, opts: dict[str, Any]) -> None:
        from swarmhil.dashboards.rerun_bridge import CameraRule, trail_steps_for  # viewer extra: rerun_bridge imports rerun

        self.mode = opts.get("viz")
        if self.mode not in MODES:
            raise ValueError(f"viz mode {self.mode!r} is not one of {MODES}")
        self.bus = bus
        self.run = run
        self.out = out
        self.opts = opts
        out.mkdir(parents=True, exist_ok=True)
        self.nice = 0
        if self.mode == "save" and type(bus).__name__ != "MemoryBus":  # own process, nobody watching live
            self.nice = os.nice(NICE)
        self.rrd: Path | None = None
        self.rec: Any = None
        self.url: str | None = None
        self.web: WebViewer | None = None
        self.camera = CameraRule.from_scenario(getattr(sc, "camera", None))
        self.trail_steps = trail_steps_for(sc.step_s, sc.orbit.mean_motion_radps, getattr(sc, "sections", {}).get("viz"))
        if self.mode == "foxglove":
            self.logger: Any = FoxgloveLive(run, sc.resolved(), port=int(opts.get("viz_port") or DEFAULT_PORT))
            self.url = self.logger.url
            (out / "viewer_url.txt").write_text(self.url + "\n")
            log.warning("foxglove: %s", self.url)
        else:
            self._open_rerun(run, sc, out, opts)
        self._lock = threading.Lock()
        self._flush_s = 0.0
        self._stop = threading.Event()
        self._start_subscriptions(bus, run)

    def _open_rerun(self, run: str, sc: Any, out: Path, opts: dict[str, Any]) -> None:
        from swarmhil.dashboards.rerun_bridge import SwarmLogger  # viewer extra: rerun_bridge imports rerun

        disable_analytics()
        self.rrd = out / "run.rrd"
        if self.mode == "serve":
            self.viz_port = int(opts.get("viz_port") or free_port())
            self.web_port = int(opts.get("web_port") or free_port())
        self.rec = open_recording(run, run, mode=self.mode, rrd=self.rrd,
                                  viz_port=getattr(self, "viz_port", None), viz_url=opts.get("viz_url"))
        if self.mode == "serve":
            (out / "logs").mkdir(exist_ok=True)
            self.web = WebViewer(self.web_port, self.viz_port, out / "logs" / "viz-web.log")
            self.url = self.web.url
            (out / "viewer_url.txt").write_text(self.url + "\n")
            log.warning("viewer: %s", self.url)
        elif self.mode == "connect":
            self.url = opts.get("viz_url") or DEFAULT_CONNECT_URL
        self.logger = SwarmLogger(self.rec, run, camera=self.camera, trail_steps=self.trail_steps, step_s=sc.step_s,
                                  config=sc.resolved())

    def _start_subscriptions(self, bus: Any, run: str) -> None:
        keys = Keys(run)
        # truth first: the logger counts step k complete once truth k+2 is in, and every telemetry of
        # step k reaches Zenoh before that truth, so draining truth before the rest never splits a step
        key_exprs = (keys.truth, keys.tm_all, f"{keys.base}/sc/*/tm/image", keys.event, keys.faults, keys.link_stats,
                     f"{keys.base}/isl/rx/*")
        landmark_kind = getattr(getattr(self.logger, "spec", None), "landmark_kind", None)
        if landmark_kind:   # paper 000: the landmark returns in the sensing stimuli
            key_exprs += (f"{keys.base}/sc/*/sense/{landmark_kind}",)
        self._rings: list[Any] = []
        self._subs: list[Any] = []
        session = getattr(bus, "session", None)
        if session is not None:
            self._rings = [ring_subscriber(session, kx) for kx in key_exprs]
        else:  # in-memory bus (in-process runs): plain callbacks
            self._subs = [bus.subscribe(kx, self._on_sample) for kx in key_exprs]
        self._timer = threading.Thread(target=self._flush_loop, name="viz-flush", daemon=True)
        self._timer.start()
        self._token = bus.declare_liveliness(keys.alive("viz"))

    def _on_sample(self, key: str, payload: bytes) -> None:
        with self._lock:
            due = self.logger.ingest(key, payload)
        if due:
            self.flush()

    def drain(self) -> int:
        """Move the samples Zenoh has queued (ring channels, truth first) into the logger."""
        n = 0
        with self._lock:
            for sub in self._rings:
                while (sample := sub.try_recv()) is not None:
                    self.logger.ingest(str(sample.key_expr), sample.payload.to_bytes())
                    n += 1
        return n

    def flush(self, final: bool = False) -> None:
        with self._lock:
            t0 = time.thread_time()
            self.logger.flush(final=final)
            self._flush_s += time.thread_time() - t0  # CPU of this thread (Rerun encodes on its own threads)

    def _flush_loop(self) -> None:
        period = FLUSH_PERIOD_S[self.mode]
        next_flush = time.monotonic() + period
        while not self._stop.wait(DRAIN_PERIOD_S):
            try:
                self.drain()
                if time.monotonic() >= next_flush:
                    self.flush()
                    next_flush = time.monotonic() + period
            except Exception:  # the viewer must never take the run down
                log.exception("viz flush failed")

    def _hold(self) -> None:
        """In-process serve runs: keep serving after the run until Ctrl-C (the launcher does it for processes)."""
        print(f"run finished; the viewer keeps serving at {self.url} until Ctrl-C", flush=True)
        try:
            while self.web is not None and self.web.proc.poll() is None:
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass

    def close(self) -> dict[str, Any]:
        t_close = time.monotonic()
        self._stop.set()
        self._timer.join(timeout=5)
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:
                pass
        flush = getattr(self.bus, "flush", None)
        if flush:
            flush()
        self.drain()
        for s in self._rings:
            try:
                s.undeclare()
            except Exception:
                pass
        self.flush(final=True)
        if self.rec is not None:
            self.rec.flush()
        close_s = time.monotonic() - t_close   # the launcher allows 10 s after SIGTERM
        if self.mode == "serve" and self.opts.get("viz_hold"):
            self._hold()
        try:
            self._token.undeclare()
        except Exception:
            pass
        if self.web is not None:
            self.web.close()
        if self.rec is not None:
            self.rec.disconnect()
        else:
            self.logger.close()   # the Foxglove server
        ru = resource.getrusage(resource.RUSAGE_SELF)
        return {"mode": self.mode, "rrd": str(self.rrd) if self.rrd else None, "url": self.url, "camera": self.camera.as_dict(),
                "trail_steps": self.trail_steps, "flush_cpu_s": round(self._flush_s, 3),
                "process_cpu_s": round(ru.ru_utime + ru.ru_stime, 3), "nice": self.nice, "close_s": round(close_s, 3), **self.logger.stats()}
