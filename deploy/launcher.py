"""`swarmhil run`: start, supervise and stop one run, multi-process over Zenoh or in-process.

Multi-process: a Zenoh router (a Python session in router mode on a free loopback port), the
recorder, one agent process per spacecraft and the plant, each its own PID. With `hosts` > 1
(deploy/mesh.py) one router per host, linked as a full mesh, each agent a client of its host's. The launcher watches
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

from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.keys import Keys
from swarmhil.deploy.companions import enabled_companions
from swarmhil.deploy.external import JoinTimeout, external_ids, join_hosts, start_external
from swarmhil.deploy.mesh import new_router_zid, process_hosts, router_name, router_users, scenario_placement
from swarmhil.deploy.netns import Hosts, NetnsError
from swarmhil.deploy.scenario import Scenario, plant_config, resolved_document

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
    truth: Any = None  # the truth as arrays (dashboards.truth_io.TruthArrays), when run_in_process kept it


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
                   opts: dict[str, Any] | None = None, record: str = "all", keep_truth: bool = False) -> RunResult:
    """Same plant, agents and recorder code in one process over the in-memory bus.

    record="all": every message; record="truth" (campaigns): the truth and the events only. Where
    the scenario allows (deploy/batch.py `why_not_batch`), the flight software of all spacecraft
    runs as one batch, fed with arrays instead of messages (the same truth, bit for bit, several
    times faster), and with record="all" its packets are written from the batch's arrays
    (deploy/batch_packets.py: the same messages, the same bytes); otherwise one agent node per
    spacecraft, as the processes (opts {"batch": False} asks for that)."""
    from swarmhil.bus.memory import MemoryBus  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.bus.recorder import RecorderNode  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.node import PlantNode  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.world import World  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if external_ids(sc):
        raise ValueError(f"{sc.source}: spacecraft {external_ids(sc)} fly external flight software (fsw = "
                         f"\"external\"): that needs a multi-process run, not an in-process one")
    run = run or new_run_id(sc.name)
    out.mkdir(parents=True, exist_ok=True)
    summary = _base_summary(sc, run, "in-process")
    bar = _Progress(sc, progress)
    wall0 = time.monotonic()
    bus = MemoryBus()
    opts = opts or {}
    rec = RecorderNode(bus, run, out / "run.mcap", config=sc.resolved(), document=resolved_document(sc), record=record,
                       background=True)  # chunks compressed on a worker thread while the run goes on
    comps = enabled_companions(sc, opts)
    from swarmhil.deploy.batch import BatchHook, why_not_batch  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    hook = None
    why = why_not_batch(sc, opts, record)
    summary["batch"] = {"used": why is None, "why_not": why}
    if why is None:
        hook = BatchHook(bus, run, sc, recorder=rec.rec if record == "all" else None)
        comps = []  # (the link channel, if any, is the hook's BatchLink)
    summary["record"] = record
    plant = PlantNode(bus, run, plant_config(sc), expect_processes=("recorder", *[c.name for c in comps]),
                      barriers=tuple(c.name for c in comps if c.barrier), progress=bar.update if progress else None,
                      local_agents=hook)
    log = None
    if keep_truth and isinstance(plant.world, World):
        from swarmhil.deploy.batch import TruthLog  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        log = plant.on_truth = TruthLog(plant.world.ids, sc.steps, plant.world.a_m, plant.world.n_radps)
    if hook is not None and hook.packets is not None:  # the recorder's Foxglove scene from the truth's arrays
        plant.on_truth = hook.packets.on_truth(list(plant.world.ids), plant.on_truth)
    started = {c.name: c.module.start(bus, run, sc, out, opts) for c in comps}
    agents = [make_agent(bus, run, sc, sid) for sid in sc.ids] if hook is None else []
    plant.wait_ready(timeout_s=1.0)
    plant_summary = plant.run()
    for name, obj in started.items():
        summary[name] = obj.close()
    if hook is not None:
        hook.close()
    if hook is not None and hook.link is not None:
        summary["channel"] = hook.link.summary()
    rec_stats = rec.close()
    bar.close()
    summary["wall_s"] = time.monotonic() - wall0
    summary["agent_faults"] = hook.faults if hook is not None else {a.id: a.faults for a in agents if a.faults}
    _finish_summary(summary, plant_summary, rec_stats, {a.id: a.rejections.total for a in agents})
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return RunResult(summary, out, truth=None if log is None else log.arrays(run))


def make_agent(bus: Any, run: str, sc: Scenario, sid: str) -> Any:
    """One spacecraft's flight software on a bus, configured from the scenario (both modes build it
    from the same JSON config: deploy/agent_image.py)."""
    from swarmhil.deploy.agent_image import agent_config, build_agent  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    return build_agent(bus, run, agent_config(sc, sid))


PR_SET_PDEATHSIG = 1
RECORDER_MAX_RESTARTS = 5  # a recorder killed mid-run is started again into a new segment, this many times


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
    root = str(Path(__file__).parents[2])  # the folder holding the `swarmhil` package (the checkout, or site-packages)
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
    poll_s = 0.05  # the supervision loop's period: how often it looks at the processes and the plant's events

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
        # ([security].auth of the scenario; `--insecure` turns it off)
        self.secure = bool(self.opts.get("secure", sc.auth))
        # mutual TLS on every link to the router, with per-run certificates (bus/tls.py):
        # [security].tls of the scenario, or `--tls`
        self.tls = bool(self.opts.get("tls", sc.tls))
        self.security: Any = None
        self.procs: dict[str, subprocess.Popen] = {}
        self.exited: dict[str, int] = {}
        self.logs: dict[str, Any] = {}
        self.all_pids: dict[str, list[int]] = {}
        self.restarts: dict[str, int] = {}
        self.recorder_segment = 0  # recorder restarts so far: it writes run.NNN.mcap (bus/mcap_tools.py)
        self._event_seq = 0
        self.cpu_budgets: dict[str, Any] = {}  # agent -> deploy.cpu_budget.CpuBudget
        self._paused: set[str] = set()  # agents a process_pause fault has SIGSTOPped
        # several hosts (deploy/mesh.py): one router per host, each agent on its host's router
        self.hosts = int(self.opts.get("hosts", 1))
        self.agent_hosts = scenario_placement(sc, self.hosts)  # ValueError: a [[spacecraft]] host outside 0 .. K-1
        self.router_eps: list[str] = []   # host -> its router's endpoint
        self.router_zids: list[str] = []  # host -> its router's Zenoh id (hosts > 1)
        self.netns: Any = None  # deploy.netns.Hosts: with opts["netns"], each host a network namespace

    def _host_of(self, name: str) -> int:
        if name.startswith("router-"):
            return int(name[len("router-"):])
        return self.agent_hosts.get(name[len("agent-"):], 0) if name.startswith("agent-") else 0

    def _router_of(self, name: str) -> str:
        """The endpoint of the router a process is a client of (its host's)."""
        return self.router_eps[self._host_of(name)]

    def _spawn(self, name: str, role: str, router: str, extra: list[str] = ()) -> None:
        cmd = [sys.executable, "-m", "swarmhil.deploy.proc", role, "--router", router, "--run", self.run,
               "--scenario", self.scenario_path, "--out", str(self.out), *extra]
        if self.security is not None:
            cmd += ["--credentials", str(self.security.credentials[name])]
            if self.security.tls is not None:
                cmd += ["--tls", str(self.security.tls.dir)]
        for opt, val in self.overrides.items():
            if val is not None:
                cmd += [f"--{opt}", str(val)]
        self._popen(name, cmd)
        if name.startswith("agent-"):
            self._limit_cpu(name)

    def _limit_cpu(self, name: str) -> None:
        """`[[spacecraft]] cpu_fraction`: the agent's process in a CPU-quota cgroup (deploy/cpu_budget.py);
        one line on stderr where the machine does not allow it."""
        fraction = self.sc.spec(name[len("agent-"):]).cpu_fraction
        if not fraction:
            return
        from swarmhil.deploy.cpu_budget import limit  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        budget = limit(self.run, name, self.procs[name].pid, fraction)
        if budget.group is None and name not in self.cpu_budgets:
            print(f"cpu budget of {name} ({fraction:g} of a core) not enforced: {budget.why_not}", file=sys.stderr,
                  flush=True)
        self.cpu_budgets[name] = budget

    def _popen(self, name: str, cmd: list[str]) -> subprocess.Popen:
        logf = open(self.out / "logs" / f"{name}.log", "ab" if name in self.logs else "wb")  # a restart appends
        if name in self.logs:
            self.logs[name].close()
        self.logs[name] = logf
        # own process group (a terminal's Ctrl-C reaches the launcher only, which stops the children
        # in order); die with the launcher (no orphans); SWARMHIL_PARENT_PID for the child's own watchdog
        env = _child_env()
        env["SWARMHIL_PARENT_PID"] = str(os.getpid())
        if self.netns is not None:  # a process of another host runs in its network namespace (deploy/netns.py)
            cmd = [*self.netns.prefix(self._host_of(name)), *cmd]
        self.procs[name] = subprocess.Popen(cmd, stdout=logf, stderr=subprocess.STDOUT, env=env,
                                            stdin=subprocess.DEVNULL, process_group=0,
                                            preexec_fn=_die_with_parent(os.getpid()))
        self.all_pids.setdefault(name, []).append(self.procs[name].pid)
        return self.procs[name]

    def _write_run_json(self, router_ep: str) -> None:
        """run.json: the router and the PIDs, current (`pids`) and every one started (`all_pids`),
        and the placement: `hosts` (host -> its router's endpoint and process) and `process_hosts`
        (process -> host)."""
        pids = {n: p.pid for n, p in self.procs.items()}
        (self.out / "run.json").write_text(json.dumps({"run": self.run, "router": router_ep, "pids": pids,
                                                       "all_pids": self.all_pids, **self._placement()}, indent=1))

    def _placement(self) -> dict[str, Any]:
        hosts = [{"host": h, "router": ep, "router_process": router_name(h),
                  **({"zid": self.router_zids[h]} if self.router_zids else {}),
                  **(self.netns.describe()[h] if self.netns is not None else {})} for h, ep in enumerate(self.router_eps)]
        ground = [n for n in self.procs if not n.startswith(("agent-", "router"))]
        procs = process_hosts(self.agent_hosts, ground)
        procs.update({router_name(h): h for h in range(len(self.router_eps))})
        return {"hosts": hosts, "process_hosts": dict(sorted(procs.items()))}

    def _supervision_event(self, watch: Any, kind: str, subject: str, detail: str, step: int) -> None:
        """An Event from the launcher (agent_restart, recorder_restart), recorded like the plant's."""
        from swarmhil.bus.codec import header  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        self._event_seq += 1
        ev = pb.Event(header=header(self.run, "launcher", step, step * self.sc.step_s, self._event_seq),
                      kind=kind, subject=subject, detail=detail)
        watch.publish(Keys(self.run).event, ev.SerializeToString())
        log.warning("%s %s: %s", kind, subject, detail)

    def _restart_recorder(self, p: subprocess.Popen, router_ep: str, watch: Any, acks: "_Acks", step: int) -> bool:
        """A recorder that died mid-run is started again into the next segment (run.001.mcap, ...);
        once it answers the flush handshake it is recording, and the launcher's Event
        `recorder_restart` (recorded in the new segment) says what was lost in between."""
        from swarmhil.bus.mcap_tools import segment_name  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        if self.recorder_segment >= RECORDER_MAX_RESTARTS:
            return False
        self.recorder_segment += 1
        seg = segment_name(self.recorder_segment)
        self._spawn("recorder", "recorder", router_ep, ["--segment", str(self.recorder_segment)])
        self._write_run_json(router_ep)
        up = self._flush_recorder(watch, acks, need_run_end=False, timeout_s=60.0) is not None
        self._supervision_event(watch, "recorder_restart", "recorder",
                                f"pid {p.pid} exited with code {p.returncode} near step {step}; recording goes on in "
                                f"{seg} (pid {self.procs['recorder'].pid}){'' if up else ', not confirmed yet'}; what "
                                f"was published in between is missing", step)
        return True

    def _merge_segments(self) -> dict[str, Any]:
        """After a recorder restart: run.mcap becomes run.000.mcap and the segments are merged into
        run.mcap (bus/mcap_tools.merge), so every reader sees one recording with the gaps listed."""
        from swarmhil.bus.mcap_tools import merge, segment_name  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        first = self.out / "run.000.mcap"
        (self.out / "run.mcap").replace(first)
        segs = [first] + [self.out / segment_name(i) for i in range(1, self.recorder_segment + 1)]
        segs = [x for x in segs if x.exists()]
        stats = merge(segs, self.out / "run.mcap")
        return {"files": [x.name for x in segs], "merged_into": "run.mcap", **stats}

    def _restarts_allowed(self, name: str, p: subprocess.Popen) -> int | None:
        """The restarts of `name` so far when [supervision] lets it restart after this exit (restart =
        "on-failure", a non-zero exit code, fewer than max_restarts); None otherwise."""
        if self.sc.restart != "on-failure" or p.returncode == 0:
            return None
        done = self.restarts.get(name, 0)
        if done >= self.sc.max_restarts:
            log.warning("%s exited with code %s; not restarted (max_restarts = %d reached)", name, p.returncode,
                        self.sc.max_restarts)
            return None
        return done

    def _restart_agent(self, name: str, p: subprocess.Popen, router_ep: str, watch: Any, step: int) -> bool:
        """[supervision] restart = "on-failure": start a dead agent again (up to max_restarts); it
        rejoins cold at the plant's next step (plant/node.py). False when the policy says no."""
        done = self._restarts_allowed(name, p)
        if done is None:
            return False
        self.restarts[name] = done + 1
        self._spawn(name, "agent", self._router_of(name), ["--id", name[len("agent-"):]])
        self._write_run_json(router_ep)
        self._supervision_event(watch, "agent_restart", name[len("agent-"):],
                                f"pid {p.pid} exited with code {p.returncode}; restart {done + 1} of "
                                f"{self.sc.max_restarts} as pid {self.procs[name].pid}", step)
        return True

    def _start_routers(self) -> str:
        """Every host's router, host 0 first; router i links to routers 0 .. i-1 (a full mesh,
        deploy/mesh.py) and is up once it has a link to each. Returns host 0's endpoint."""
        for host in range(self.hosts):
            self.router_eps.append(self._start_router(host))
        return self.router_eps[0]

    def _start_router(self, host: int = 0, attempts: int = 8, timeout_s: float = 120.0, port: int | None = None) -> str:
        """A host's router as its own process (`python -m swarmhil.deploy.router`, deploy/router.py), on a free loopback
        port: the launcher is not the router. A port taken before the router bound it (exit code 4)
        draws another one (`port` given, a restart on the same endpoint: it fails instead). Returns the
        endpoint once the router accepts connections (and, in a mesh, has linked to the routers of the
        hosts before it)."""
        import socket

        from swarmhil.bus.zenoh_bus import endpoint, free_loopback_port  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        name = router_name(host)
        address = "127.0.0.1" if self.netns is None else self.netns.addresses[host]
        fixed = port
        starts = self._linked_lines(name) + 1  # a restart appends to its log: this start's "linked" line
        for _attempt in range(1 if fixed else attempts):
            port = fixed or (free_loopback_port() if self.netns is None else self.netns.free_port(host))
            ep = endpoint(port, host=address, proto="tls" if self.tls else "tcp")
            cmd = [sys.executable, "-m", "swarmhil.deploy.router", "--listen", ep]
            if self.opts.get("join_listen") and host == 0:  # external flight software on another host (deploy/external.py)
                cmd += ["--also-listen", self.opts["join_listen"]]
            if self.security is not None:
                cmd += ["--acl-dir", str(self.security.dir)]
                if self.security.tls is not None:
                    cmd += ["--tls", str(self.security.tls.dir)]
            if self.router_zids:
                cmd += ["--zid", self.router_zids[host]]
            if host > 0:
                cmd += [x for other in self.router_eps[:host] for x in ("--connect", other)]
                cmd += ["--link-timeout", f"{timeout_s:g}"]
                if self.security is not None:
                    cmd += ["--credentials", str(self.security.credentials[name])]
            p = self._popen(name, cmd)
            t_end = time.monotonic() + timeout_s
            while p.poll() is None and time.monotonic() < t_end:
                try:
                    with socket.create_connection((address, port), timeout=0.5):
                        if host == 0 or self._linked_lines(name) >= starts:
                            return ep
                except OSError:
                    pass
                time.sleep(0.05)
            if p.poll() is None:
                self._stop([name])
                raise RunFailed(f"{name} did not listen on {ep}{' and link to the other routers' if host else ''} "
                                f"within {timeout_s:.0f} s:\n{self._tail(name)}")
            if p.returncode != 4:
                raise RunFailed(f"{name} exited with code {p.returncode}:\n{self._tail(name)}")
            log.warning("router port %s was taken before it bound it; trying another", ep)
        raise RunFailed(f"no free loopback port for {name} after {attempts} attempts")

    def _linked_lines(self, name: str) -> int:
        """How many times a mesh router has printed that it linked to every router it connects to
        (deploy/router.py): once per start, its log appended to on a restart."""
        try:
            return (self.out / "logs" / f"{name}.log").read_text(errors="replace").count("router mesh: linked to")
        except OSError:
            return 0

    def _router_names(self) -> list[str]:
        """The routers started, host 0's last (the order to stop them in)."""
        return [n for n in self.procs if n.startswith("router-")][::-1] + (["router"] if "router" in self.procs else [])

    def _restart_router(self, name: str, p: subprocess.Popen, watch: Any, step: int) -> bool:
        """[supervision] restart = "on-failure": start a non-first host's router again on its endpoint
        (its Zenoh id and links as before); the host's agents' sessions reconnect to it (within
        deploy/proc.py ROUTER_GRACE_S, or they exit and are restarted as crashed agents) and the plant
        takes them back at its next step. Event `router_restart`. False when the policy says no or the
        router does not come back (then `_router_lost`)."""
        done = self._restarts_allowed(name, p)
        if done is None:
            return False
        host = int(name[len("router-"):])
        try:
            self._start_router(host, timeout_s=60.0, port=int(self.router_eps[host].rpartition(":")[2]))
        except RunFailed as exc:
            log.error("%s could not be restarted: %s", name, exc)
            return False
        finally:
            self.restarts[name] = done + 1
        self.exited.pop(name, None)
        self._write_run_json(self.router_eps[0])
        self._supervision_event(watch, "router_restart", name,
                                f"pid {p.pid} exited with code {p.returncode}; restart {done + 1} of "
                                f"{self.sc.max_restarts} as pid {self.procs[name].pid} on {self.router_eps[host]}", step)
        return True

    def _router_lost(self, name: str, p: subprocess.Popen, watch: Any, step: int) -> None:
        """A non-first host's router exited: its agents' liveliness tokens go with it, so the plant
        marks them dead (their spacecraft coast) and the run goes on; recorded as an Event
        `router_lost` from the launcher."""
        host = int(name[len("router-"):])
        lost = sorted(sid for sid, h in self.agent_hosts.items() if h == host)
        self._supervision_event(watch, "router_lost", name,
                                f"pid {p.pid} exited with code {p.returncode} near step {step}; host {host}'s agents "
                                f"{', '.join(lost) or '(none)'} lose the run", step)

    def _signal(self, name: str, sig: int) -> None:
        p = self.procs.get(name)
        if p is not None and p.poll() is None:
            os.kill(p.pid, sig)  # by PID, never by name

    def _act_on_fault(self, event: str, kind: str, targets: list[str]) -> None:
        """A process fault the plant announced at its step (plant/node.py): the plant has already
        taken the agent out of the lockstep; here its process is killed (process_crash: SIGKILL,
        then [supervision] restart decides), or frozen and thawed (process_pause: SIGSTOP, SIGCONT)."""
        for sid in targets:
            name = f"agent-{sid}"
            if kind == "process_crash" and event == "fault_start":
                log.warning("fault: process_crash of %s (pid %s)", name, getattr(self.procs.get(name), "pid", None))
                self._signal(name, signal.SIGKILL)
            elif kind == "process_pause" and event == "fault_start":
                self._signal(name, signal.SIGSTOP)
                self._paused.add(name)
            elif kind == "process_pause" and event == "fault_end" and name in self._paused:
                self._signal(name, signal.SIGCONT)
                self._paused.discard(name)

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
        from swarmhil.bus.recorder import flush_key  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

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

    def _make_security(self) -> Any:
        """The run's credentials, ACL and certificates (bus/acl.py, bus/tls.py): the launcher's own
        credential, or None for an open run."""
        if not self.secure:
            if self.tls:
                raise RunFailed("TLS needs the run's credentials: --tls cannot be combined with --insecure")
            return None
        from swarmhil.bus.acl import make_run_security  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        users = ["launcher", "plant", "recorder", *[c.name for c in self.companions], *[f"agent-{s}" for s in self.sc.ids]]
        if self.hosts > 1:
            self.router_zids = [new_router_zid() for _ in range(self.hosts)]
            users += router_users(self.hosts)
        self.security = make_run_security(self.out, self.run, users, tls=self.tls,
                                          tls_hosts=[*join_hosts(self.opts.get("join_listen")),
                                                     *(self.netns.addresses if self.netns is not None else [])],
                                          router_zids=self.router_zids)
        return self.security.credential("launcher")

    def execute(self) -> RunResult:
        from swarmhil.bus.recorder import ack_key  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
        from swarmhil.bus.zenoh_bus import ZenohBus  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        from swarmhil.deploy.memory import check_memory  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        check_memory(self.sc, n_ground=2 + len(self.companions))  # plant, recorder, companions: refuse before any start
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "logs").mkdir(exist_ok=True)
        # every child reads the one validated document (after --set), not the user's file
        # (and each agent only its own config: no scenario validation in an agent image)
        from swarmhil.deploy.agent_image import write_resolved_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        write_resolved_scenario(self.sc, self.out / "scenario.json")
        self.scenario_path = str((self.out / "scenario.json").resolve())
        summary = _base_summary(self.sc, self.run, "multi-process")
        wall0 = time.monotonic()
        if self.opts.get("netns"):
            try:
                self.netns = Hosts(self.hosts)
            except NetnsError as exc:
                raise RunFailed(str(exc)) from None
        try:
            launcher_cred = self._make_security()
        except BaseException:
            if self.netns is not None:
                self.netns.close()
            raise
        try:
            router_ep = self._start_routers()
            watch = ZenohBus(router_ep, credential=launcher_cred)
        except BaseException:
            self._stop(self._router_names())
            for f in self.logs.values():
                f.close()
            if self.netns is not None:
                self.netns.close()
            raise
        summary["router"] = router_ep
        summary.update(self._placement())
        summary["secure"] = self.secure
        summary["tls"] = self.tls
        bar = _Progress(self.sc, self.progress)
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
        stalled: list[str] = []  # agents the plant dropped on a lockstep stall: killed, so restarted
        if self.sc.restart == "on-failure":
            watch.subscribe(keys.event, lambda _k, p: stalled.extend(_stalled_agent(p)))
        process_faults: list[tuple[str, str, list[str]]] = []  # [[fault]] process_*: the plant's events, acted here
        if any(f.family == "process" for f in self.sc.faults):
            watch.subscribe(keys.faults, lambda _k, p: process_faults.extend(_process_fault(p)))
        reason, code, interrupted = "", 0, False
        joins = None
        old_term = _on_sigterm_raise()
        try:
            self._spawn("recorder", "recorder", router_ep)
            for c in self.companions:
                self._spawn(c.name, "companion", router_ep, ["--name", c.name, "--opts", json.dumps(self.opts)])
            external = set(external_ids(self.sc))  # flight software the launcher does not start (docs/hil.md)
            for sid in self.sc.ids:
                if sid not in external:
                    self._spawn(f"agent-{sid}", "agent", self._router_of(f"agent-{sid}"), ["--id", sid])
            self._spawn("plant", "plant", router_ep,
                        ["--companions", ",".join(c.name for c in self.companions),
                         "--barriers", ",".join(c.name for c in self.companions if c.barrier)])
            summary["pids"] = {n: p.pid for n, p in self.procs.items()}
            self._write_run_json(router_ep)
            joins = start_external(self, watch, router_ep)
            while True:
                if joins is not None and not stepping.is_set():
                    joins.check(router_ep)  # JoinTimeout: one line naming the spacecraft and endpoint
                rc = self.procs["plant"].poll()
                if rc is not None:
                    # a process fault the plant announced just before it ended is still acted on: the
                    # plant already counted that agent crashed (tests/test_faults.py, a fast lockstep run)
                    while process_faults:
                        self._act_on_fault(*process_faults.pop(0))
                    if rc != 0:
                        reason, code = f"plant exited with code {rc}:\n{self._tail('plant')}", 1
                    break
                for n, p in list(self.procs.items()):
                    if n not in self.exited and p.poll() is not None:
                        if stepping.is_set() and n.startswith("agent-") and self._restart_agent(n, p, router_ep, watch, bar.last):
                            continue
                        if n == "recorder" and stepping.is_set() and self._restart_recorder(p, router_ep, watch, acks, bar.last):
                            continue
                        self.exited[n] = p.returncode
                        if n == "router":
                            raise RunFailed(f"the router (pid {p.pid}) exited with code {p.returncode}; every "
                                            f"process stops:\n{self._tail(n)}")
                        if n.startswith("router-"):  # another host's router: its agents lose the run, or rejoin
                            if not (stepping.is_set() and self._restart_router(n, p, watch, bar.last)):
                                self._router_lost(n, p, watch, bar.last)
                            continue
                        if n == "recorder" or any(c.name == n and c.barrier for c in self.companions):
                            raise RunFailed(f"{n} exited with code {p.returncode}; the run cannot go on:\n{self._tail(n)}")
                        if not stepping.is_set():  # the plant would wait for it in vain
                            raise RunFailed(f"{n} (pid {p.pid}) exited with code {p.returncode} at start-up; "
                                            f"last lines of {self.out / 'logs' / (n + '.log')}:\n{self._tail(n)}")
                        log.warning("%s (pid %d) exited with code %s; the plant counts it dead", n, p.pid, p.returncode)
                while process_faults:
                    self._act_on_fault(*process_faults.pop(0))
                while stalled:  # alive but silent past the stall timeout: end it, the restart policy follows
                    name = f"agent-{stalled.pop()}"
                    if name in self.procs and self.procs[name].poll() is None:
                        log.warning("%s stalled the lockstep; SIGKILL (pid %d) to restart it", name, self.procs[name].pid)
                        self._signal(name, signal.SIGKILL)
                time.sleep(self.poll_s)
        except KeyboardInterrupt:
            interrupted, reason, code = True, "interrupted (Ctrl-C)", 130
        except _Terminated:
            interrupted, reason, code = True, "interrupted (SIGTERM)", 143
        except RunFailed as exc:
            reason, code = str(exc), 1
        except JoinTimeout as exc:
            reason, code = str(exc), 1
            summary["external_join_timeout"] = True
        finally:
            for name in sorted(self._paused):  # a stopped process would not see its SIGTERM
                self._signal(name, signal.SIGCONT)
            router_up = self.procs["router"].poll() is None
            # an external agent that never joined: no step ran, nothing to wait for in the recording
            confirm = router_up and not summary.get("external_join_timeout")
            self._stop(["plant"], timeout_s=30.0)
            # the recorder has the plant's final truth and run_end (and everything the router had
            # before them) before the agents go; a plant that failed publishes no run_end
            plant = self.procs.get("plant")
            if confirm:
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
            final_ack = self._flush_recorder(watch, acks, need_run_end=False) if confirm else None
            summary["recorder_confirmed"] = final_ack is not None
            self._stop(["recorder"], timeout_s=30.0)
            bar.close()
            watch.close()
            self._stop(self._router_names())
            for f in self.logs.values():
                f.close()
            if self.netns is not None:
                self.netns.close()
            if old_term is not None:
                signal.signal(signal.SIGTERM, old_term)
        summary["wall_s"] = time.monotonic() - wall0
        summary["interrupted"] = interrupted
        summary["exit_codes"] = {n: p.returncode for n, p in self.procs.items()}
        summary["restarts"] = dict(self.restarts)
        if self.cpu_budgets:  # (every agent has exited: the groups' counters are final)
            from swarmhil.deploy.cpu_budget import release  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

            summary["cpu_budgets"] = {n: b.summary() for n, b in self.cpu_budgets.items()}
            for b in self.cpu_budgets.values():
                release(b)
        if self.recorder_segment:
            try:
                summary["recording_segments"] = self._merge_segments()
            except Exception as exc:  # noqa: BLE001 - the segments stay; `swarmhil mcap merge` can be run by hand
                log.error("merging the recording's segments failed: %s", exc)
                summary["recording_segments"] = {"error": f"{type(exc).__name__}: {exc}"}
        summary["all_pids"] = self.all_pids
        if joins is not None:
            summary["external"] = joins.summary()
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


def _stalled_agent(payload: bytes) -> list[str]:
    """[id] when an event is the plant dropping an agent on a lockstep stall (plant/node.py)."""
    try:
        ev = pb.Event.FromString(payload)
    except Exception:  # noqa: BLE001 - not an event: nothing to do
        return []
    if ev.kind == "agent_dead" and ev.header.source == "plant" and ev.detail.startswith("lockstep stall"):
        return [ev.subject]
    return []


def _process_fault(payload: bytes) -> list[tuple[str, str, list[str]]]:
    """[(fault_start | fault_end, kind, targets)] when an event on `faults` is a process fault's."""
    try:
        ev = pb.Event.FromString(payload)
        f = json.loads(ev.detail)
    except Exception:  # noqa: BLE001 - not a fault event: nothing to do
        return []
    if ev.header.source != "plant" or not str(f.get("kind", "")).startswith("process_"):
        return []
    return [(ev.kind, f["kind"], list(f.get("targets", [])))]


def _read_json(p: Path) -> dict[str, Any] | None:
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None
