"""Issues 11 and 25: a mission room from outside the source tree (contract, fsw, sense, report; a
package named by the scenario's [run].rooms) adds a controller, a sensing kind and a report section
through the registries, with a body, and flies multi-process with no edit to plant, agent, bus or
launcher code; each process loads only its own part of the room, and `swarmhil report` puts the
room's section on the run's page (docs/adding-a-mission.md is the recipe this test follows).

The toy: three spacecraft on the CW propagator chase a slot 20 m from a drifting, spinning rock (a
kinematic [[body]]); the toy sensing kind measures the rock relative to each spacecraft, the toy
controller is a PD on it, limited by norm. Multi-process and in-process runs must give the same
truth bit for bit, and the physics must be the CW solution of the commands the agents recorded.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from conftest import read_mcap

# The toy mission is a room outside the source tree (docs/adding-a-mission.md): a package laid out like
# missions/<room>/, one module per process that runs it, named by the scenario's [run].rooms.
TOY_ROOM = {
    "__init__.py": '"""A toy mission room, outside the source tree. Imports nothing (each process loads its part)."""\n',
    "contract.py": """
        \"\"\"What the toy's plant side and flight side both spell: names only (numpy and bus at most).\"\"\"
        CONTROLLER = "toy-pd"
        SENSING = "toy-rock"
        ROCK_KIND = "rock"
        ROCK_REL_POSITION = "rock_rel_position_m"
        ROCK_REL_VELOCITY = "rock_rel_velocity_mps"
        SLOT_M = 20.0
        """,
    "fsw.py": """
        \"\"\"The toy's flight software: a PD on the rock's relative position towards a slot SLOT_M away.\"\"\"
        from dataclasses import dataclass, fields

        import numpy as np

        from swarmhil.agent.controller import Command, register

        from .contract import CONTROLLER, ROCK_REL_POSITION, ROCK_REL_VELOCITY, SLOT_M


        @dataclass(frozen=True)
        class ToyParams:
            kp: float = 1e-3
            kd: float = 0.05
            slot_m: float = SLOT_M
            max_accel_mps2: float = 1e-3

            @classmethod
            def parse(cls, params):
                known = {f.name for f in fields(cls)}
                unknown = sorted(set(params) - known)
                if unknown:
                    raise ValueError(f"unknown parameter {unknown[0]!r}; known: {sorted(known)}")
                p = cls(**{k: float(v) for k, v in params.items()})
                if min(p.kp, p.kd, p.slot_m, p.max_accel_mps2) <= 0:
                    raise ValueError("kp, kd, slot_m and max_accel_mps2 must be positive")
                return p


        class ToyPd:
            name = CONTROLLER

            def __init__(self, p):
                self.p = p

            def step(self, obs):
                rel = obs.extra[ROCK_REL_POSITION]
                vel = obs.extra[ROCK_REL_VELOCITY]
                d = float(np.linalg.norm(rel))
                err = rel - self.p.slot_m * rel / max(d, 1e-9)
                return Command(accel_mps2=self.p.kp * err + self.p.kd * vel, mode="chase")


        @register(CONTROLLER, validate=ToyParams.parse)
        def _toy(sc_id, orbit, params):
            return ToyPd(ToyParams.parse(params))
        """,
    "sense.py": """
        \"\"\"The toy's sensing kind (the plant's side): the rock relative to each spacecraft.\"\"\"
        from swarmhil.bus import swarmhil_pb2 as pb
        from swarmhil.bus.codec import add_measurement
        from swarmhil.plant.sensing import register_sensing

        from .contract import ROCK_KIND, ROCK_REL_POSITION, ROCK_REL_VELOCITY, SENSING


        @register_sensing(SENSING)
        class RockSensor:
            message = pb.Measurements

            def __init__(self, scenario):
                pass

            def stimulus(self, ctx, j, hdr):
                rock = next(b for b in ctx.world.body_truth() if b.spec.kind == ROCK_KIND)
                msg = pb.Measurements(header=hdr, u_rad=ctx.u_rad)
                add_measurement(msg, ROCK_REL_POSITION, rock.position_m - ctx.position_m[j])
                add_measurement(msg, ROCK_REL_VELOCITY, rock.velocity_mps - ctx.velocity_mps[j])
                return msg
        """,
    "report.py": """
        \"\"\"The toy's report section (the reporter's side): each spacecraft's distance from its slot at the end.\"\"\"
        import numpy as np

        from swarmhil.dashboards.sections import SectionContext, SectionResult, register_section, uses_controller

        from .contract import CONTROLLER, ROCK_KIND, SLOT_M


        @register_section("toy-rock-chase", applies=lambda cfg: uses_controller(cfg, CONTROLLER))
        def rock_chase(ctx: SectionContext) -> SectionResult:
            truth = ctx.truth  # the spacecraft; the rock is kinematic: its motion is in the recorded configuration
            motion = next(b for b in ctx.config["body"] if b["kind"] == ROCK_KIND)["motion"]
            rock = np.add(motion["position_m"], np.multiply(motion["velocity_mps"], truth.t_s[-1]))
            err = {sid: abs(float(np.linalg.norm(truth.position_m[-1, i] - rock)) - SLOT_M)
                   for i, sid in enumerate(truth.ids)}
            rows = "".join(f"<tr><td>{sid}</td><td>{e:.3f}</td></tr>" for sid, e in err.items())
            return SectionResult(title="Toy rock chase", metrics={"final_slot_error_m": err},
                                 html=f"<table><tr><th>spacecraft</th><th>final |distance - slot| (m)</th></tr>{rows}</table>")
        """,
}

SCENARIO = """
[run]
name = "toy"
duration_s = 300.0
step_s = 5.0
seed = 2
rooms = ["toy_room"]

[orbit]
semi_major_axis_m = 6878137.0

[plant]
fidelity = "cw"

[actuator]
limit = "norm"
max_accel_mps2 = 2e-3

[controller]
name = "toy-pd"

[sensing]
kind = "toy-rock"

[[spacecraft]]
id = "a"
position_m = [0.0, 200.0, 0.0]

[[spacecraft]]
id = "b"
position_m = [50.0, -150.0, 20.0]
velocity_mps = [0.0, 0.1, 0.0]
params = {kp = 2e-3}

[[spacecraft]]
id = "c"
position_m = [-60.0, 0.0, -80.0]
max_accel_mps2 = 5e-4

[[body]]
id = "rock"
kind = "rock"
mass_kg = 500.0
shape = {kind = "ellipsoid", semi_axes_m = [3.0, 2.0, 1.0]}
motion = {kind = "kinematic", position_m = [0.0, 10.0, 0.0], velocity_mps = [0.0, 0.02, 0.0], spin_axis = [0.0, 0.0, 1.0], spin_rate_radps = 0.05}
"""


def _truth(path: Path) -> tuple[dict[int, bytes], dict[int, object]]:
    raw, msgs = {}, {}
    for topic, _lt, _pt, m in read_mcap(path):
        if topic == "truth":
            raw[int(m.header.step)], msgs[int(m.header.step)] = m.SerializeToString(), m
    return raw, msgs


@pytest.fixture(scope="module")
def toy_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("toy")
    (d / "outside" / "toy_room").mkdir(parents=True)
    for name, text in TOY_ROOM.items():
        (d / "outside" / "toy_room" / name).write_text(textwrap.dedent(text).lstrip())
    (d / "toy.toml").write_text(SCENARIO)
    env = dict(os.environ, PYTHONPATH=str(d / "outside"), SWARMHIL_IMPORT_AUDIT=str(d / "audit"))
    (d / "audit").mkdir()
    outs = []
    for label, extra in (("mp", []), ("ip", ["--in-process"])):
        out = d / label
        r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(d / "toy.toml"), "--out", str(out),
                            "--no-progress", "--run-id", "toy-run", *extra], capture_output=True, text=True, cwd=d, env=env, timeout=300)
        assert r.returncode == 0, r.stderr + r.stdout
        outs.append(out)
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "report", str(outs[0]), "--no-vector"], capture_output=True,
                       text=True, cwd=d, env=env, timeout=300)
    assert r.returncode == 0, r.stderr + r.stdout
    return outs[0], outs[1]


def test_toy_mission_flies_multi_process_through_the_registries(toy_runs: tuple[Path, Path]) -> None:
    mp, ip = toy_runs
    raw_mp, truth = _truth(mp / "run.mcap")
    raw_ip, _ = _truth(ip / "run.mcap")
    assert len(raw_mp) == 61 and raw_mp.keys() == raw_ip.keys()
    assert all(raw_mp[k] == raw_ip[k] for k in raw_mp)  # same truth, bit for bit
    last = truth[max(truth)]
    bodies = {b.id: b for b in last.bodies}
    rock = bodies["rock"]
    assert rock.kind == "rock"
    # the kinematic rock: p0 + v t, spin about z at 0.05 rad/s: q = (cos(wt/2), 0, 0, sin(wt/2)) (scalar first)
    t = last.header.t
    assert [rock.position_m.x, rock.position_m.y, rock.position_m.z] == pytest.approx([0.0, 10.0 + 0.02 * t, 0.0], abs=1e-12)
    assert rock.attitude.w == pytest.approx(np.cos(0.025 * t), abs=1e-12)
    assert rock.attitude.z == pytest.approx(np.sin(0.025 * t), abs=1e-12)
    # the toy controller worked: every spacecraft closer to its 20 m slot than it started
    first = {b.id: b for b in truth[0].bodies}
    for sid in ("a", "b", "c"):
        d0 = np.linalg.norm([first[sid].position_m.x, first[sid].position_m.y - 10.0, first[sid].position_m.z])
        p = np.array([bodies[sid].position_m.x, bodies[sid].position_m.y, bodies[sid].position_m.z])
        d1 = np.linalg.norm(p - [0.0, 10.0 + 0.02 * t, 0.0])
        # c has a quarter of the thrust (5e-4 m/s^2): it closes in, a and b halve their error at least
        assert abs(d1 - 20.0) < (0.9 if sid == "c" else 0.5) * abs(d0 - 20.0), (sid, d0, d1)


def test_toy_truth_is_the_cw_solution_of_the_limited_commands(toy_runs: tuple[Path, Path]) -> None:
    """Independent check: propagate the recorded initial state with the closed-form HCW solution
    (scipy expm of the augmented system) under the recorded per-step commands; limits by norm
    (2e-3, and 5e-4 for c) must hold in every recorded command."""
    from scipy.linalg import expm

    _raw, truth = _truth(toy_runs[0] / "run.mcap")
    n = np.sqrt(3.986004418e14 / 6878137.0**3)
    A = np.zeros((9, 9))
    A[0:3, 3:6] = np.eye(3)
    A[3, 0], A[3, 4], A[4, 3], A[5, 2] = 3 * n * n, 2 * n, -2 * n, -n * n
    A[3:6, 6:9] = np.eye(3)
    M = expm(A * 5.0)
    limit = {"a": 2e-3, "b": 2e-3, "c": 5e-4}
    for sid in ("a", "b", "c"):
        st = None
        for k in sorted(truth):
            b = next(x for x in truth[k].bodies if x.id == sid)
            p = np.array([b.position_m.x, b.position_m.y, b.position_m.z])
            v = np.array([b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z])
            if st is not None:
                # 1e-6 m: exact discretisations of the same linear ODE, round-off over 60 steps
                assert np.abs(st[:3] - p).max() < 1e-6, (sid, k)
            a = np.array([b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z])
            assert np.linalg.norm(a) <= limit[sid] * (1 + 1e-12)
            nxt = next((x for x in truth.get(k + 1, truth[k]).bodies if x.id == sid), None)
            a_next = np.array([nxt.accel_cmd_mps2.x, nxt.accel_cmd_mps2.y, nxt.accel_cmd_mps2.z])
            st = (M @ np.concatenate([p, v, a_next]))  # accel_cmd of step k+1 = the command held over [k, k+1)


def test_each_process_loads_its_own_part_of_the_outside_room(toy_runs: tuple[Path, Path]) -> None:
    """The room from outside the tree is split by process like the tree's rooms: the plant imports
    its sense and no fsw, each agent its fsw and no sense or report (deploy/proc.py's import audit)."""
    audit = toy_runs[0].parent / "audit"
    roles = {f.stem: json.loads(f.read_text()) for f in audit.glob("*.json")}
    assert {"plant", "agent-a", "agent-b", "agent-c"} <= set(roles), sorted(roles)
    toy = {name: {p for p in r["room_parts"] if p.startswith("toy_room.")} for name, r in roles.items()}
    assert toy["plant"] == {"toy_room.contract", "toy_room.sense"}, toy["plant"]
    for sid in "abc":
        assert toy[f"agent-{sid}"] == {"toy_room.contract", "toy_room.fsw"}, toy[f"agent-{sid}"]
    assert not any(p.endswith((".fsw", ".report")) for p in roles["plant"]["room_parts"]), roles["plant"]["room_parts"]


def test_the_outside_rooms_section_is_on_the_report_page(toy_runs: tuple[Path, Path]) -> None:
    """`swarmhil report` imports the room named by the recorded configuration and runs its section:
    its metric is the truth's (each spacecraft's final |distance to the rock - 20 m|), on the page."""
    mp = toy_runs[0]
    summary = json.loads((mp / "summary.json").read_text())
    err = summary["metrics"]["toy-rock-chase"]["final_slot_error_m"]
    _raw, truth = _truth(mp / "run.mcap")
    last = {b.id: np.array([b.position_m.x, b.position_m.y, b.position_m.z]) for b in truth[max(truth)].bodies}
    for sid in "abc":
        assert err[sid] == pytest.approx(abs(np.linalg.norm(last[sid] - last["rock"]) - 20.0), abs=1e-9), sid
    html = (mp / "report" / "index.html").read_text()
    assert "Toy rock chase" in html and f"{err['a']:.3f}" in html


def test_a_room_that_is_not_there_is_a_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENARIO.replace('rooms = ["toy_room"]', 'rooms = ["no_such_room"]'))
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "run", str(bad), "--out", str(tmp_path / "o"),
                        "--no-progress"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert r.returncode != 0 and "[run].rooms" in r.stderr and "no_such_room" in r.stderr, r.stderr
    assert r.stderr.strip().count("\n") == 0, r.stderr  # one line, no traceback


def test_a_report_without_the_room_says_so_and_writes_the_rest(toy_runs: tuple[Path, Path], tmp_path: Path) -> None:
    """`swarmhil report` where the recording's outside room does not import (not on PYTHONPATH):
    one line on stderr names the room and that its section is left out; the page is written."""
    import shutil

    run = tmp_path / "copy"
    shutil.copytree(toy_runs[1], run)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "report", str(run), "--no-vector"], capture_output=True,
                       text=True, cwd=tmp_path, env=env, timeout=300)
    assert r.returncode == 0, r.stderr + r.stdout
    lines = [ln for ln in r.stderr.splitlines() if "toy_room" in ln]
    assert len(lines) == 1 and "left out" in lines[0], r.stderr
    html = (run / "report" / "index.html").read_text()
    assert "Toy rock chase" not in html and "<html" in html.lower()
