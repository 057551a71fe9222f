"""A second external flight computer (examples/external_fsw_second/fc2.py), written from docs/hil.md and
a join kit alone: one file, no asyncio, no numpy, protobuf code generated from the kit's own proto.
It flies sc02 of hil-3 and the run's truth is the built-in run's, bit for bit. Real processes over
real Zenoh on loopback; recordings read with the standard readers (the patterns of test_external_fsw.py).
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS, read_mcap
from swarmhil.deploy.scenario import load_scenario

SCENARIO = SCENARIOS / "hil-3.toml"
SWARMHIL = [sys.executable, "-m", "swarmhil.deploy.cli"]
FC2 = ROOT / "examples" / "external_fsw_second" / "fc2.py"
PROJECT_PACKAGES = {"agent", "bus", "claims", "dashboards", "deploy", "link", "missions", "plant", "swarmhil"}

AUDIT = """
import json, runpy, sys
out, sys.argv = sys.argv[1], sys.argv[2:]
try:
    runpy.run_path(sys.argv[0], run_name="__main__")
finally:
    with open(out, "w") as f:
        json.dump(sorted({m.split(".")[0] for m in sys.modules}), f)
"""
"""`python -c AUDIT MODULES.json fc2.py ARGS...`: fc2.py as a script, then the top-level modules it imported."""


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _fc2_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location("fc2_under_test", FC2)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # (its dataclasses look their module up there)
    spec.loader.exec_module(mod)
    return mod


def _doc_comparison() -> dict:
    """docs/hil.md's "Checking bit for bit" Python (truth_of, same_truth), as the guide gives it."""
    import re

    (code,) = [c for c in re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "hil.md").read_text(), re.S)
               if "def same_truth" in c]
    ns: dict = {}
    exec(compile(code, "docs/hil.md", "exec"), ns)  # noqa: S102
    return ns


def _wait_for_kit(launcher: subprocess.Popen, kit: Path) -> None:
    t_end = time.monotonic() + 120
    while not (kit / "join.json").exists():
        assert launcher.poll() is None, launcher.communicate()
        assert time.monotonic() < t_end, "no join kit after 120 s"
        time.sleep(0.1)


def _fly(tmp_path: Path, name: str, run_id: str, args: list[str], kit_of=lambda kit: kit) -> tuple[Path, str, Path]:
    """`swarmhil run hil-3 ARGS` with sc02 flown by fc2.py from its kit (or from kit_of(kit)), outside
    the repository, with nothing of the project on its path. (run dir, fc2's output, its module list)."""
    out = tmp_path / name
    launcher = subprocess.Popen([*SWARMHIL, "run", str(SCENARIO), "--out", str(out), "--run-id", run_id, "--no-progress",
                                 *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), cwd=ROOT)
    try:
        kit = out / "external" / "sc02"
        _wait_for_kit(launcher, kit)
        audit = tmp_path / f"{name}-fc2-modules.json"
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        fc = subprocess.run([sys.executable, "-c", AUDIT, str(audit), str(FC2), str(kit_of(kit))], capture_output=True,
                            text=True, env=env, cwd=tmp_path, timeout=300)
        l_out, l_err = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    assert fc.returncode == 0 and launcher.returncode == 0, (fc.stdout, fc.stderr, l_out, l_err)
    return out, fc.stdout, audit


def _builtin(tmp_path: Path, run_id: str, overrides: list[str]) -> tuple[Path, dict]:
    """The same scenario with sc02's built-in flight software, multi-process, as the reference."""
    from swarmhil.deploy.launcher import MultiProcessRun

    sc = load_scenario(SCENARIO, ["spacecraft.1.fsw=builtin", *overrides]).with_overrides(duration_s=1000.0)
    ref = MultiProcessRun(str(SCENARIO), sc, tmp_path / "builtin", run_id, progress=False,
                          overrides={"duration": 1000.0}).execute()
    assert ref.exit_code == 0, ref.reason
    return tmp_path / "builtin", ref.summary


def _assert_same_flight(ext: Path, ref: Path, ref_summary: dict) -> list[float]:
    """Truth and sc02's commands byte for byte the built-in run's; a clean summary. sc02's along-track commands."""
    doc = _doc_comparison()  # the comparison the guide describes
    assert len(doc["truth_of"](str(ext))) == 101 and doc["same_truth"](str(ext), str(ref))  # bytes, log times
    assert len(doc["truth_of"](str(ext), "sc/sc02/act")) == 100
    assert doc["same_truth"](str(ext), str(ref), "sc/sc02/act")  # every field of every command
    s = json.loads((ext / "summary.json").read_text())
    assert s["steps"] == 100 and s["dead_agents"] == {} and s["rejected_packets"] == 0, s
    assert s["late_commands"] == 0 and not s["missed_deadlines"] and s["delta_v_mps"] == ref_summary["delta_v_mps"], s
    msgs = read_mcap(ext / "run.mcap")
    tm = [m for t, _l, _p, m in msgs if t == "sc/sc02/tm"]
    assert len(tm) == 100 and {m.controller for m in tm} == {"drift-null/fc2"}  # the recording says who flew it
    uy = [m.accel_mps2.y for t, _l, _p, m in msgs if t == "sc/sc02/act"]
    assert all(u != 0.0 for u in uy) and s["delta_v_mps"]["sc02"] > 0  # a law of its stimuli, not the null one
    return uy


def test_fc2_law_is_the_built_in_controller_bit_for_bit() -> None:
    """fc2's drift-null (pure Python floats, numpy's pairwise summation reproduced) against the built-in
    controller, 0 to 40 neighbours: past 8 values numpy sums pairwise, past 128 it splits (checked on
    np.mean directly up to 400 values)."""
    from swarmhil.agent.controller import Observation, OrbitInfo
    from swarmhil.agent.controllers import DriftNullController

    fc2 = _fc2_module()
    rng = np.random.default_rng(2)

    def spread(shape: tuple[int, ...], lo: float, hi: float) -> np.ndarray:
        """Values of either sign over many decades, 10**lo .. 10**hi."""
        return rng.uniform(-1.0, 1.0, shape) * 10.0 ** rng.uniform(lo, hi, shape)

    for k in range(1, 401):
        v = spread((k,), -3, 3)
        assert fc2.mean_like_numpy(v.tolist()) == np.mean(v), k
    assert fc2.mean_like_numpy([-0.0]) == 0.0 and str(fc2.mean_like_numpy([-0.0])) == str(np.mean([-0.0]))
    n, checked, clipped, long = 0.0011067834463349404, 0, 0, 0
    for k in rng.integers(0, 41, 3000):
        pos, vel, (gain, amax) = spread((k, 3), -2, 3), spread((k, 3), -4, 0), 10.0 ** rng.uniform(-5, -2, 2)
        ids = [f"n{i}" for i in range(k)]
        built_in = DriftNullController(OrbitInfo(7e6, n), gain, amax).step(
            Observation(step=0, t_s=0.0, u_rad=0.0, neighbour_ids=ids, rel_position_m=pos, rel_velocity_mps=vel))
        accel, mode = fc2.Law("drift-null", n, float(gain), float(amax)).decide(list(zip(pos[:, 0].tolist(),
                                                                                         vel[:, 1].tolist())))
        assert tuple(built_in.accel_mps2.tolist()) == accel and built_in.mode == mode, (k, built_in, accel)
        checked += 1
        clipped += abs(accel[1]) == amax
        long += k >= 8
    assert checked == 3000 and 100 < clipped < 2900 and long > 1500  # both clip branches, many pairwise sums


def test_fc2_refuses_a_kit_it_cannot_fly_in_one_line(tmp_path: Path) -> None:
    """No kit, or a kit naming a law fc2 does not fly: one line on stderr, exit 2, nothing joined."""
    from swarmhil.bus.acl import make_run_security
    from swarmhil.deploy.external import write_join_kit

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([sys.executable, str(FC2), str(tmp_path / "nowhere")], capture_output=True, text=True, env=env,
                       timeout=60)
    assert r.returncode == 2 and r.stderr == f"fc2: {tmp_path}/nowhere/join.json: no such file (the launcher writes " \
                                             "it last: is the run started?)\n", r.stderr
    (tmp_path / "secrets").mkdir()
    sec = make_run_security(tmp_path / "secrets", "kr", ["plant", "agent-sc02"], tls=False)
    kit = write_join_kit(tmp_path / "run", load_scenario(SCENARIO), "kr", "sc02", ["tcp/127.0.0.1:1"], sec)
    doc = json.loads((kit / "join.json").read_text())
    doc["agent"]["controller"] = "sabatini"
    (kit / "join.json").write_text(json.dumps(doc))
    r = subprocess.run([sys.executable, str(FC2), str(kit)], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "agent.controller 'sabatini' is not a law this flight computer flies (null, drift-null)" in r.stderr


def test_second_flight_computer_flies_bit_identical_to_the_built_in(tmp_path: Path) -> None:
    """sc02 of hil-3 flown by fc2.py (from its kit only; it imports nothing of the project, nor numpy) in a
    multi-process lockstep run: the truth and sc02's commands are byte for byte the built-in run's, and
    the summary shows no dead spacecraft and no rejected packet."""
    ext, fc_out, audit = _fly(tmp_path, "ext", "hil2a", ["--duration", "1000"])
    assert "fc2: sc02 answered 100 stimuli (last step 99); 0 rejected; router gone, leaving" in fc_out, fc_out
    modules = set(json.loads(audit.read_text()))
    assert {"zenoh", "google", "swarmhil_pb2"} <= modules and not modules & (PROJECT_PACKAGES | {"numpy"}), modules
    ref, ref_summary = _builtin(tmp_path, "hil2a", [])
    uy = _assert_same_flight(ext, ref, ref_summary)
    assert len(set(uy)) > 50


def test_second_flight_computer_from_a_copied_kit_over_mutual_tls_with_a_decision_period(tmp_path: Path) -> None:
    """`--tls` and `[controller].decision_period_s = 30` (3 steps): fc2 flies from a copy of the kit (the
    launcher's kit has lost its TLS files, so only the copy's `tls` names can work), holds each decision
    for 3 steps; truth and commands are the built-in run's (on loopback, without TLS) bit for bit."""
    from system_tools import require_command

    require_command("openssl", "openssl")

    def copied(kit: Path) -> Path:
        moved = tmp_path / "elsewhere" / "kit"
        shutil.copytree(kit, moved)
        shutil.rmtree(kit / "tls")  # the zenoh block's absolute paths now point nowhere
        return moved

    period = ["controller.decision_period_s=30"]
    ext, fc_out, _audit = _fly(tmp_path, "tls", "hil2b", ["--duration", "1000", "--tls", "--set", period[0]], copied)
    assert "fc2: sc02 answered 100 stimuli" in fc_out, fc_out
    doc = json.loads((tmp_path / "elsewhere" / "kit" / "join.json").read_text())
    assert doc["timing"]["decision_period_steps"] == 3 and doc["tls"]
    s = json.loads((ext / "summary.json").read_text())
    assert s["tls"] and s["secure"], s
    ref, ref_summary = _builtin(tmp_path, "hil2b", period)
    uy = _assert_same_flight(ext, ref, ref_summary)
    assert all(uy[k] == uy[k - k % 3] for k in range(100)) and len(set(uy)) == 34  # held between decisions


@pytest.mark.system
def test_second_flight_computer_frozen_past_the_stall_timeout_rejoins_and_flies_on(tmp_path: Path) -> None:
    """Lockstep with a 2 s stall timeout: fc2 frozen (SIGSTOP, by its PID) for 3.2 s, less than its 5 s
    lease, so its token stays up: the plant drops sc02 ("lockstep stall"), nobody tells fc2; thawed, it
    sees no stimulus for stall_timeout_s + its margin, declares its token again and the plant takes it
    back (one rejoin); sc02 is alive at the end and fc2 flew to the last step."""
    import signal

    out = tmp_path / "rejoin"
    launcher = subprocess.Popen([*SWARMHIL, "run", str(SCENARIO), "--out", str(out), "--run-id", "hil2c", "--no-progress",
                                 "--duration", "100000", "--set", "supervision.stall_timeout_s=2.0"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(), cwd=ROOT)
    fc = None
    try:
        kit = out / "external" / "sc02"
        _wait_for_kit(launcher, kit)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        fc = subprocess.Popen([sys.executable, str(FC2), str(kit), "--rejoin-margin-s", "1.0"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
        assert fc.stdout.readline().startswith("fc2: sc02 joined run hil2c")
        time.sleep(0.5)  # flying
        os.kill(fc.pid, signal.SIGSTOP)
        time.sleep(3.2)
        os.kill(fc.pid, signal.SIGCONT)
        fc_out, fc_err = fc.communicate(timeout=300)
        l_out, l_err = launcher.communicate(timeout=120)
    finally:
        for p in (fc, launcher):
            if p is not None and p.poll() is None:
                p.kill()
    assert fc.returncode == 0 and launcher.returncode == 0, (fc_out, fc_err, l_out, l_err)
    assert "dropped; declaring the token again" in fc_err and "(last step 9999)" in fc_out, (fc_out, fc_err)
    s = json.loads((out / "summary.json").read_text())
    (rejoin,) = s["rejoins"]
    assert rejoin["id"] == "sc02" and rejoin["dead_reason"].startswith("lockstep stall") and rejoin["step"] > rejoin["dead_step"]
    assert s["steps"] == 10000 and s["dead_agents"] == {} and s["rejected_packets"] == 0, s
