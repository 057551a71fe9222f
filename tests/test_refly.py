"""`swarmhil refly RUN --agent ID` (issue 26): one agent's flight software re-flown alone on what the
recording says it received, every command compared with the recorded one.

- paper 002 with the rendered camera and the EKF: an unchanged agent re-flies bit for bit (recorded
  in-process here; multi-process in tests/test_system_camera.py);
- paper 004 (servicing-6, its own sensing kind and link traffic), recorded in-process: the same,
  and `--until` stops early;
- a changed gain (paper 002's collision-avoidance along-track offset, which acts only on a pair in
  collision avoidance) diverges first at the step the agent's own telemetry shows its first pair in
  collision avoidance, read independently from the recording;
- a recording without the agent's stimuli, an unknown agent, and a --set the controller refuses:
  one line each, exit 1, 1 and 2.
"""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from swarmhil.bus import swarmhil_pb2 as pb
from conftest import SCENARIOS
from swarmhil.deploy.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent


def swarmhil(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def run_in_process(scenario: str, out: Path, duration_s: float, *extra: str) -> Path:
    r = swarmhil("run", str(SCENARIOS / scenario), "--in-process", "--out", str(out), "--duration", str(duration_s),
                 "--no-progress", *extra)
    assert r.returncode == 0, r.stderr
    return out


def first_collision_avoidance_steps(mcap: Path) -> dict[str, int]:
    """{agent: first step whose telemetry holds a pair in collision avoidance}, from the recording."""
    first: dict[str, int] = {}
    with open(mcap, "rb") as f:
        for _s, ch, m in make_reader(f).iter_messages(log_time_order=False):
            parts = ch.topic.split("/")
            if len(parts) == 3 and parts[0] == "sc" and parts[2] == "tm" and parts[1] not in first:
                tm = pb.Telemetry.FromString(m.data)
                if any(d.behaviour == "collision_avoidance" for d in tm.decisions):
                    first[parts[1]] = int(tm.header.step)
    return first


def nonzero_commands(table: Path) -> int:
    with table.open() as f:
        return sum(1 for row in csv.DictReader(f)
                   if any(float(row[k]) != 0.0 for k in ("recorded_ax", "recorded_ay", "recorded_az")))


def test_camera_ekf_agent_reflies_bit_for_bit(tmp_path: Path) -> None:
    """Recorded in-process here (the default tier's time); the camera system test re-flies an agent of
    its multi-process recording too (tests/test_system_camera.py)."""
    sc = load_scenario(SCENARIOS / "sabatini-20-camera-filter.toml")
    assert sc.sensing["kind"] == "scene" and sc.sections["nav"]["navigator"] == "ekf"
    run = run_in_process("sabatini-20-camera-filter.toml", tmp_path / "run", 600.0)
    for sid in ("sc01", "sc13"):
        r = swarmhil("refly", str(run), "--agent", sid, "--exit-code")
        print(r.stdout.strip())
        assert r.returncode == 0, r.stdout + r.stderr
        assert r.stdout.startswith(f"{sid}: identical over 60 steps (commands and transmissions, bit for bit)"), r.stdout
        # the camera, the EKF and the controller really acted: commands recorded and re-flown are not all zero
        assert nonzero_commands(run / f"refly-{sid}" / "commands.csv") > 10
        assert (run / f"refly-{sid}" / "command-difference.png").stat().st_size > 0


def test_servicing_agent_reflies_bit_for_bit_and_until_stops_early(tmp_path: Path) -> None:
    run = run_in_process("servicing-6.toml", tmp_path / "run", 10.0)
    r = swarmhil("refly", str(run), "--agent", "s3", "--exit-code")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith("s3: identical over 100 steps"), r.stdout
    assert nonzero_commands(run / "refly-s3" / "commands.csv") > 50
    r = swarmhil("refly", str(run), "--agent", "s3", "--until", "2.5", "--out", str(tmp_path / "until"))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("s3: identical over 26 steps"), r.stdout  # steps 0..25: t <= 2.5 s
    with (tmp_path / "until" / "commands.csv").open() as f:
        assert len(list(csv.DictReader(f))) == 26


def test_changed_gain_diverges_first_where_it_first_acts(tmp_path: Path) -> None:
    run = run_in_process("sabatini-20.toml", tmp_path / "run", 1800.0)
    first_ca = first_collision_avoidance_steps(run / "run.mcap")
    late = {sid: k for sid, k in first_ca.items() if k > 0}
    assert late, f"no agent enters collision avoidance after step 0 in 30 min: {first_ca}"
    sid, step = max(late.items(), key=lambda kv: kv[1])  # the latest first use: the sharpest check
    same = swarmhil("refly", str(run), "--agent", sid, "--exit-code")
    assert same.returncode == 0 and "identical over 180 steps" in same.stdout, same.stdout + same.stderr
    r = swarmhil("refly", str(run), "--agent", sid, "--set", "controller.params.ca_da_offset_m=120", "--exit-code")
    print(r.stdout.strip())
    assert r.returncode == 5, r.stdout + r.stderr
    assert r.stdout.startswith(f"{sid}: first divergence at step {step} (t = {step * 10:g} s): accel_mps2."), r.stdout
    with (run / f"refly-{sid}" / "divergences.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert int(rows[0]["step"]) == step and float(rows[0]["recorded"]) != float(rows[0]["now"])


def test_bad_input_one_line_each(tmp_path: Path) -> None:
    run = run_in_process("servicing-6.toml", tmp_path / "truth-only", 1.0, "--record", "truth")
    r = swarmhil("refly", str(run), "--agent", "s3")
    assert r.returncode == 1 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        f"error: {run / 'run.mcap'}: the recording holds no stimuli for s3 (topic sc/s3/sense/p004-partial); "
        "refly needs a recording of every message (`swarmhil run` without --record truth)"]
    full = run_in_process("servicing-6.toml", tmp_path / "full", 1.0)
    r = swarmhil("refly", str(full), "--agent", "sc09")
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1
    assert "no spacecraft 'sc09' in this run (it flew s1, s2, s3, s4, s5, s6)" in r.stderr
    r = swarmhil("refly", str(full), "--agent", "s3", "--set", "controller.params.no_such_gain=1")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "unknown p004-lbdnn parameters ['no_such_gain']" in r.stderr
