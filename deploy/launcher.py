"""`swarmhil run`: start, supervise and stop one run, multi-process over Zenoh or in-process.

Multi-process: a Zenoh router (a Python session in router mode on a free loopback port), the
recorder, one agent process per spacecraft and the plant, each its own PID. The launcher watches
them; at the end (or on Ctrl-C) it stops the plant, then the agents, then the recorder (so the
recording holds everything), by PID only, and writes DIR/summary.json.
"""
from __future__ import annotations

import json
import logging
import os
import secrets
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from tqdm import tqdm

from bus import swarmhil_pb2 as pb
from bus.keys import Keys
from deploy.companions import enabled_companions
from deploy.scenario import Scenario, resolved_document

log = logging.getLogger("swarmhil.launcher")


class RunFailed(RuntimeError):
    pass


def new_run_id(name: str) -> str:
    return f"{name}-{datetime.now(timezone.utc):%Y%m%dT%H%M%S}-{secrets.token_hex(2)}"


@dataclass
class RunResult:
    summary: dict[str, Any]
    out: Path
    exit_code: int = 0
    reason: str = ""
    pids: dict[str, int] = field(default_factory=dict)


def _base_summary(sc: Scenario, run: str, mode_label: str) -> dict[str, Any]:
    return {
        "run": run,
        "scenario": sc.name,
        "scenario_file": sc.source,
        "mode": sc.mode,
        "process_mode": mode_label,
        "seed": sc.seed,
        "fidelity": sc.fidelity,
        "controller": sc.controller,
        "agents": len(sc.ids),
        "step_s": sc.step_s,
        "duration_s": sc.duration_s,
        "reference_orbit": {"semi_major_axis_m": sc.orbit.semi_major_axis_m,
                            "mean_motion_radps": sc.orbit.mean_motion_radps,
                            "inclination_deg": sc.orbit.inclination_rad * 57.29577951308232},
        "config": sc.resolved(),  # the fully resolved configuration (also MCAP metadata "swarmhil.config")
    }


def _finish_summary(summary: dict[str, Any], plant: dict[str, Any], rec: dict[str, Any], agents_rejected: dict[str, int]) -> dict[str, Any]:
    summary.update(plant)
    plant_rej = plant.get("rejected_packets", {}) if plant else {}
    by_proc = {"plant": int(plant_rej.get("plant", 0)), **{f"agent-{k}": v for k, v in sorted(agents_rejected.items())}}
    summary["rejected_packets"] = sum(by_proc.values())
    summary["rejected_packets_by_process"] = by_proc
    summary["rejected_packets_by_key"] = plant_rej.get("plant_by_key", {})
    summary["recording"] = rec
    summary.setdefault("dead_agents", {})
    summary.setdefault("delta_v_mps", {})
    summary.setdefault("delta_v_total_mps", 0.0)
    return summary


class _Progress:
    def __init__(self, sc: Scenario, enabled: bool) -> None:
        self.sc = sc
        self.bar = tqdm(total=sc.steps, unit="step", disable=not enabled, dynamic_ncols=True,
                        bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} steps [{elapsed}<{remaining}] {postfix}")
        self.wall0 = time.monotonic()
        self.last = 0

    def update(self, step: int, _wall: float | None = None) -> None:
        if step <= self.last:
            return
        self.bar.update(step - self.last)
        self.last = step
        wall = time.monotonic() - self.wall0
        t = step * self.sc.step_s
        self.bar.set_postfix_str(f"t={t / 3600:.2f} h  x{t / max(wall, 1e-9):.0f} real time", refresh=False)

    def close(self) -> None:
        self.bar.close()


def run_in_process(sc: Scenario, out: Path, run: str | None = None, progress: bool = False,
                   opts: dict[str, Any] | None = None, record: str = "all") -> RunResult:
    """Same plant, agents and recorder code in one process over the in-memory bus.

    record="all": every message, one agent node per spacecraft (as the processes). record="truth"
    (issue 16, campaigns): the recording holds the truth and the events only, and where the
    scenario allows (deploy/batch.py) the flight software of all spacecraft runs as one batch, fed
    with arrays instead of messages: the same truth, bit for bit, several times faster."""
    from bus.memory import MemoryBus
    from bus.recorder import RecorderNode
    from plant.node import PlantNode

    run = run or new_run_id(sc.name)
    out.mkdir(parents=True, exist_ok=True)
    summary = _base_summary(sc, run, "in-process")
    bar = _Progress(sc, progress)
    wall0 = time.monotonic()
    bus = MemoryBus()
    opts = opts or {}
    rec = RecorderNode(bus, run, out / "run.mcap", config=sc.resolved(), document=resolved_document(sc), record=record)
    comps = enabled_companions(sc, opts)
    hook = None
    if record == "truth":
        from deploy.batch import BatchHook, why_not_batch

        why = why_not_batch(sc, opts)
        summary["batch"] = {"used": why is None, "why_not": why}
        if why is None:
            hook = BatchHook(bus, run, sc)
    summary["record"] = record
    plant = PlantNode(bus, run, sc, expect_processes=("recorder", *[c.name for c in comps]),
                      barriers=tuple(c.name for c in comps if c.barrier), progress=bar.update if progress else None,
                      local_agents=hook)
    started = {c.name: c.module.start(bus, run, sc, out, opts) for c in comps}
    agents = [make_agent(bus, run, sc, sid) for sid in sc.ids] if hook is None else []
    plant.wait_ready(timeout_s=1.0)
    plant_summary = plant.run()
    for name, obj in started.items():
        summary[name] = obj.close()
    rec_stats = rec.close()
    bar.close()
    summary["wall_s"] = time.monotonic() - wall0
    summary["agent_faults"] = hook.faults if hook is not None else {a.id: a.faults for a in agents if a.faults}
    _finish_summary(summary, plant_summary, rec_stats, {a.id: a.rejections.total for a in agents})
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return RunResult(summary, out)


def make_agent(bus: Any, run: str, sc: Scenario, sid: str) -> Any:
    """One spacecraft's flight software on a bus, configured from the scenario (both modes build it
    from the same JSON config: deploy/agent_image.py)."""
    from deploy.agent_image import agent_config, build_agent

    return build_agent(bus, run, agent_config(sc, sid))


PR_SET_PDEATHSIG = 1


def _die_with_parent(parent_pid: int) -> Any:
    """preexec_fn of every child: SIGTERM when the launcher dies, even by SIGKILL (Linux
    PR_SET_PDEATHSIG, kept across exec); the child then stops as on the launcher's SIGTERM, so the
    recorder still closes its MCAP. Closes the race where the launcher died before the prctl.
    (Linux sends it when the *thread* that forked exits: `execute` starts and stops every child on
    one thread, which outlives them.)"""
    import ctypes

    try:  # looked up in the parent: no dlopen between fork and exec (the launcher has threads)
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # not Linux: the child's parent watchdog (deploy/proc.py) remains
        prctl = None
    sigterm = int(signal.SIGTERM)

    def preexec() -> None:
        if prctl is not None:
            prctl(PR_SET_PDEATHSIG, sigterm, 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(1)
    return preexec


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    env.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"})
    root = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


class _Terminated(BaseException):
    """SIGTERM reached the launcher (`timeout`, a cancelled CI job): stop like on Ctrl-C."""


def _on_sigterm_raise() -> Any:
    """Make SIGTERM interrupt the launcher's main loop; the previous handler, or None when the run
    is not on the main thread (then signals stay as they are)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(_sig: int, _frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # once: the orderly stop must not be cut short
        raise _Terminated()
    return signal.signal(signal.SIGTERM, handler)


class MultiProcessRun:
    def __init__(self, scenario_path: str, sc: Scenario, out: Path, run: str | None = None, progress: bool = True,
                 overrides: dict[str, Any] | None = None, opts: dict[str, Any] | None = None) -> None:
        self.scenario_path = str(Path(scenario_path).resolve())
        self.sc = sc
        self.out = out
        self.run = run or new_run_id(sc.name)
        self.progress = progress
        self.overrides = overrides or {}
        self.opts = opts or {}
        self.companions = enabled_companions(sc, self.opts)
        # authentication and access control on the router (bus/acl.py); off only by explicit choice
        self.secure = bool(self.opts.get("secure", True))
        self.security: Any = None
        self.procs: dict[str, subprocess.Popen] = {}
        self.exited: dict[str, int] = {}
        self.logs: dict[str, Any] = {}

    def _spawn(self, name: str, role: str, router: str, extra: list[str] = ()) -> None:
        cmd = [sys.executable, "-m", "deploy.proc", role, "--router", router, "--run", self.run,
               "--scenario", self.scenario_path, "--out", str(self.out), *extra]
        if self.security is not None:
            cmd += ["--credentials", str(self.security.credentials[name])]
        for opt, val in self.overrides.items():
            if val is not None:
                cmd += [f"--{opt}", str(val)]
        logf = open(self.out / "logs" / f"{name}.log", "wb")
        self.logs[name] = logf
        # own process group (a terminal's Ctrl-C reaches the launcher only, which stops the children
        # in order); die with the launcher (no orphans); --parent-pid for the child's own watchdog
        env = _child_env()
        env["SWARMHIL_PARENT_PID"] = str(os.getpid())
        self.procs[name] = subprocess.Popen(cmd, stdout=logf, stderr=subprocess.STDOUT, env=env,
                                            stdin=subprocess.DEVNULL, process_group=0,
                                            preexec_fn=_die_with_parent(os.getpid()))

    def _signal(self, name: str, sig: int) -> None:
        p = self.procs.get(name)
        if p is not None and p.poll() is None:
            os.kill(p.pid, sig)  # by PID, never by name

    def _stop(self, names: list[str], timeout_s: float = 10.0) -> None:
        for n in names:
            self._signal(n, signal.SIGTERM)
        t_end = time.monotonic() + timeout_s
        for n in names:
            p = self.procs[n]
            try:
                p.wait(max(0.1, t_end - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("%s (pid %d) did not stop on SIGTERM; SIGKILL", n, p.pid)
                self._signal(n, signal.SIGKILL)
                p.wait()

    def _flush_recorder(self, watch: Any, acks: "_Acks", need_run_end: bool, timeout_s: float = 15.0) -> dict[str, Any] | None:
        """Flush handshake with the recorder (bus/recorder.py): ask, over Zenoh, what it has written,
        until it answers (and, with need_run_end, until the plant's run_end event is among it: the
        plant publishes its final truth and then run_end on one session, so both are recorded).
        Everything that reached the router before the request is covered by the answer. Bounded:
        on timeout a warning says what may be missing, and the shutdown goes on."""
        from bus.recorder import flush_key

        t_end = time.monotonic() + timeout_s
        ack: dict[str, Any] | None = None
        while time.monotonic() < t_end:
            if self.procs.get("recorder") is None or self.procs["recorder"].poll() is not None:
                log.warning("recorder is not running; cannot confirm the recording is complete")
                return None
            nonce = secrets.token_hex(8)
            watch.publish(flush_key(self.run), nonce.encode())
            ack = acks.wait(nonce, min(1.0, max(0.05, t_end - time.monotonic())))
            if ack is not None and (ack["run_end"] or not need_run_end):
                return ack
            time.sleep(0.05)
        what = "the plant's run_end event" if need_run_end else "an answer"
        log.warning("recorder did not confirm %s within %.0f s (last answer: %s); the recording may miss the "
                    "last messages", what, timeout_s, None if ack is None else f"{ack['messages']} messages")
        return None

    def _tail(self, name: str, lines: int = 15) -> str:
        try:
            return "\n".join((self.out / "logs" / f"{name}.log").read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def execute(self) -> RunResult:
        from bus.recorder import ack_key
        from bus.zenoh_bus import ZenohBus, open_loopback_router

        from deploy.memory import check_memory

        check_memory(self.sc, n_ground=2 + len(self.companions))  # plant, recorder, companions: refuse before any start
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "logs").mkdir(exist_ok=True)
        # every child reads the one validated document (after --set), not the user's file
        # (and each agent only its own config: no scenario validation in an agent image)
        from deploy.agent_image import write_resolved_scenario

        write_resolved_scenario(self.sc, self.out / "scenario.json")
        self.scenario_path = str((self.out / "scenario.json").resolve())
        summary = _base_summary(self.sc, self.run, "multi-process")
        wall0 = time.monotonic()
        launcher_cred = None
        if self.secure:
            from bus.acl import make_run_security

            users = ["launcher", "plant", "recorder", *[c.name for c in self.companions], *[f"agent-{s}" for s in self.sc.ids]]
            self.security = make_run_security(self.out, self.run, users)
            launcher_cred = self.security.credential("launcher")
        # retries when the free port is taken before Zenoh binds it
        router, router_ep = open_loopback_router(overrides=self.security.router_overrides() if self.security else None)
        summary["router"] = router_ep
        summary["secure"] = self.secure
        bar = _Progress(self.sc, self.progress)
        watch = ZenohBus(router_ep, credential=launcher_cred)
        keys = Keys(self.run)

        stepping = threading.Event()  # the plant has started step 0: every process came up

        def on_tick(_key: str, payload: bytes) -> None:
            stepping.set()
            try:
                bar.update(int(pb.Tick.FromString(payload).header.step))
            except Exception:
                pass

        watch.subscribe(keys.clock, on_tick)
        acks = _Acks()
        watch.subscribe(ack_key(self.run), acks.put)
        reason, code, interrupted = "", 0, False
        old_term = _on_sigterm_raise()
        try:
            self._spawn("recorder", "recorder", router_ep)
            for c in self.companions:
                self._spawn(c.name, "companion", router_ep, ["--name", c.name, "--opts", json.dumps(self.opts)])
            for sid in self.sc.ids:
                self._spawn(f"agent-{sid}", "agent", router_ep, ["--id", sid])
            self._spawn("plant", "plant", router_ep,
                        ["--companions", ",".join(c.name for c in self.companions),
                         "--barriers", ",".join(c.name for c in self.companions if c.barrier)])
            summary["pids"] = {n: p.pid for n, p in self.procs.items()}
            (self.out / "run.json").write_text(json.dumps({"run": self.run, "router": router_ep, "pids": summary["pids"]}, indent=1))
            while True:
                rc = self.procs["plant"].poll()
                if rc is not None:
                    if rc != 0:
                        reason, code = f"plant exited with code {rc}:\n{self._tail('plant')}", 1
                    break
                for n, p in self.procs.items():
                    if n not in self.exited and p.poll() is not None:
                        self.exited[n] = p.returncode
                        if n == "recorder" or any(c.name == n and c.barrier for c in self.companions):
                            raise RunFailed(f"{n} exited with code {p.returncode}; the run cannot go on:\n{self._tail(n)}")
                        if not stepping.is_set():  # the plant would wait for it in vain
                            raise RunFailed(f"{n} (pid {p.pid}) exited with code {p.returncode} at start-up; "
                                            f"last lines of {self.out / 'logs' / (n + '.log')}:\n{self._tail(n)}")
                        log.warning("%s (pid %d) exited with code %s; the plant counts it dead", n, p.pid, p.returncode)
                time.sleep(0.05)
        except KeyboardInterrupt:
            interrupted, reason, code = True, "interrupted (Ctrl-C)", 130
        except _Terminated:
            interrupted, reason, code = True, "interrupted (SIGTERM)", 143
        except RunFailed as exc:
            reason, code = str(exc), 1
        finally:
            self._stop(["plant"], timeout_s=30.0)
            # the recorder has the plant's final truth and run_end (and everything the router had
            # before them) before the agents go; a plant that failed publishes no run_end
            plant = self.procs.get("plant")
            self._flush_recorder(watch, acks, need_run_end=plant is not None and plant.returncode == 0)
            self._stop([n for n in self.procs if n.startswith("agent-")])
            if self.opts.get("viz") == "serve" and not interrupted and not code:
                bar.close()
                print("run finished; the viewer keeps serving until Ctrl-C", flush=True)
                try:
                    while self.procs.get("viz") is not None and self.procs["viz"].poll() is None:
                        time.sleep(0.2)
                except KeyboardInterrupt:
                    pass
            self._stop([c.name for c in self.companions])
            # the agents and companions have exited, so what they published is at the router, before
            # this request: once answered, it is recorded
            final_ack = self._flush_recorder(watch, acks, need_run_end=False)
            summary["recorder_confirmed"] = final_ack is not None
            self._stop(["recorder"], timeout_s=30.0)
            bar.close()
            watch.close()
            router.close()
            for f in self.logs.values():
                f.close()
            if old_term is not None:
                signal.signal(signal.SIGTERM, old_term)
        summary["wall_s"] = time.monotonic() - wall0
        summary["interrupted"] = interrupted
        summary["exit_codes"] = {n: p.returncode for n, p in self.procs.items()}
        plant_s = _read_json(self.out / "plant_summary.json")
        rec_s = _read_json(self.out / "recorder_summary.json")
        agents_rej, faults = {}, {}
        for sid in self.sc.ids:
            a = _read_json(self.out / "agents" / f"{sid}.json")
            agents_rej[sid] = int(a.get("rejected_packets", 0)) if a else 0
            if a and a.get("faults"):
                faults[sid] = a["faults"]
        summary["agent_faults"] = faults
        for c in self.companions:
            summary[c.name] = _read_json(self.out / f"{c.name}_summary.json") or {}
        _finish_summary(summary, plant_s or {}, rec_s or {}, agents_rej)
        if code:
            summary["failure"] = reason
        (self.out / "summary.json").write_text(json.dumps(summary, indent=1))
        return RunResult(summary, self.out, code, reason, summary.get("pids", {}))


class _Acks:
    """The recorder's flush answers (JSON), by nonce, for the launcher's waits."""

    def __init__(self) -> None:
        import threading

        self._cv = threading.Condition()
        self._by_nonce: dict[str, dict[str, Any]] = {}

    def put(self, _key: str, payload: bytes) -> None:
        try:
            ack = json.loads(payload)
        except ValueError:
            return
        with self._cv:
            self._by_nonce[str(ack.get("nonce"))] = ack
            self._cv.notify_all()

    def wait(self, nonce: str, timeout_s: float) -> dict[str, Any] | None:
        with self._cv:
            self._cv.wait_for(lambda: nonce in self._by_nonce, timeout_s)
            return self._by_nonce.pop(nonce, None)


def _read_json(p: Path) -> dict[str, Any] | None:
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None
