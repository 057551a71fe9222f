"""Runs with the viewer bridge (issue 6): run.rrd verified by `rerun rrd verify`, read back with
Rerun's reader and compared with the recording's truth (read with the mcap reader and its
protobuf decoder, not the project's code), and `swarmhil replay` giving the same views.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from swarmhil.dashboards.replay import read_rrd
from swarmhil.dashboards.viz_node import disable_analytics, rerun_exe
from conftest import sigint_default
from swarmhil.dashboards.rerun_bridge import MODE_COLOURS
from test_viz_bridge import blueprints_in
from swarmhil.deploy.cli import main as cli_main

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "deploy" / "scenarios"


def mcap_truth(path: Path) -> dict[int, tuple[list[str], np.ndarray]]:
    """{step: (ids, positions (N, 3))} of the spacecraft in the recording's truth messages."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out = {}
    with open(path, "rb") as f:
        for _s, ch, _m, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            if ch.topic == "truth":
                sc = [b for b in msg.bodies if b.kind != "target"]
                out[msg.header.step] = ([b.id for b in sc],
                                        np.array([[b.position_m.x, b.position_m.y, b.position_m.z] for b in sc]))
    return out


def rrd_verify(path: Path) -> None:
    disable_analytics()
    r = subprocess.run([rerun_exe(), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"rerun rrd verify {path}: {r.stdout}{r.stderr}"


def check_positions_equal_truth(rrd: Path, mcap: Path, steps: list[int] | None = None) -> int:
    rows = read_rrd(rrd)["/world/swarm"]
    labels = rows["Points3D:labels"][-1]
    truth = mcap_truth(mcap)
    assert truth, "no truth in the recording"
    assert set(rows["Points3D:positions"]) == set(truth), "a step of the truth is missing from run.rrd (or extra)"
    for step in steps or sorted(truth):
        ids, pos = truth[step]
        assert labels == ids
        np.testing.assert_array_equal(np.array(rows["Points3D:positions"][step]), pos.astype(np.float32),
                                      err_msg=f"positions at step {step}")
    return len(truth)


def replay_verified(mcap: Path, rrd: Path) -> Path:
    """`swarmhil replay MCAP --rrd RRD`, which must succeed and pass `rerun rrd verify`."""
    res = CliRunner().invoke(cli_main, ["replay", str(mcap), "--rrd", str(rrd)])
    assert res.exit_code == 0, res.output
    rrd_verify(rrd)
    return rrd


def check_scene(rrd: Path, mcap: Path, camera: bool = True) -> None:
    """Issue 18: one blueprint; a frame per spacecraft at every step of the truth (position equal to
    it); a camera frustum (Pinhole) per spacecraft where the scenario has the camera."""
    assert blueprints_in(rrd) == 1
    rows = read_rrd(rrd)
    truth = mcap_truth(mcap)
    ids = truth[min(truth)][0]
    for i, sid in enumerate(ids):
        tf = rows[f"/world/sc/{sid}"]
        assert set(tf["Transform3D:translation"]) == set(truth), sid
        for step, (_ids, pos) in truth.items():
            np.testing.assert_array_equal(np.array(tf["Transform3D:translation"][step][0]), pos[i].astype(np.float32))
        assert set(tf["Transform3D:quaternion"]) == set(truth)
        assert (f"/world/sc/{sid}/camera" in rows) == camera
        if camera:
            assert rows[f"/world/sc/{sid}/camera"]["Pinhole:image_from_camera"][-1]
        assert set(rows[f"/metrics/delta_v_by_spacecraft/{sid}"]["Scalars:scalars"]) == set(truth)
    assert set(rows["/world/thrust"]["Arrows3D:vectors"]) == set(truth)


def latest_at(rows: dict[int, object], t: int) -> object:
    ts = [s for s in rows if s <= t]
    return rows[max(ts)] if ts else None


def check_same_views(live: Path, replayed: Path) -> None:
    a, b = read_rrd(live), read_rrd(replayed)
    paths = lambda d: {e for e in d if e != "/__properties"}  # noqa: E731
    assert paths(a) == paths(b)
    for entity in paths(a):
        assert set(a[entity]) == set(b[entity]), entity
        for comp, rows in a[entity].items():
            steps = sorted(set(rows) | set(b[entity][comp]))
            for t in steps:
                assert latest_at(rows, t) == latest_at(b[entity][comp], t), f"{entity} {comp} at step {t}"


@pytest.fixture(scope="module")
def in_process_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    out = tmp_path_factory.mktemp("viz-inproc")
    sc = load_scenario(SCENARIOS / "demo.toml").with_overrides(duration_s=400.0)
    res = run_in_process(sc, out, "viz-inproc", opts={"viz": "save"})
    assert res.summary["viz"]["samples"]["truth"] == sc.steps + 1
    return out


def test_in_process_rrd_verifies_and_holds_the_truth(in_process_run: Path) -> None:
    rrd_verify(in_process_run / "run.rrd")
    assert check_positions_equal_truth(in_process_run / "run.rrd", in_process_run / "run.mcap") == 41
    check_scene(in_process_run / "run.rrd", in_process_run / "run.mcap")


def test_replay_gives_the_same_entities_and_values(in_process_run: Path, tmp_path: Path) -> None:
    out = replay_verified(in_process_run / "run.mcap", tmp_path / "replay.rrd")
    check_same_views(in_process_run / "run.rrd", out)
    check_scene(out, in_process_run / "run.mcap")


def test_replay_refuses_a_broken_recording(tmp_path: Path) -> None:
    bad = tmp_path / "run.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 64)
    res = CliRunner().invoke(cli_main, ["replay", str(bad), "--rrd", str(tmp_path / "x.rrd")])
    assert res.exit_code != 0 and "mcap repair" in res.output


def test_viz_option_validation() -> None:
    res = CliRunner().invoke(cli_main, ["run", str(SCENARIOS / "demo.toml"), "--viz", "bogus"])
    assert res.exit_code == 2 and "--viz" in res.output


def _cli_run(scenario: Path, out: Path, duration_s: float) -> None:
    cmd = [sys.executable, "-m", "swarmhil.deploy.cli", "run", str(scenario), "--viz", "save", "--out", str(out),
           "--duration", str(duration_s), "--no-progress"]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["viz"]["rrd"].endswith("run.rrd") and summary["viz"]["rejected"] == 0


def test_multi_process_run_with_viz_save(tmp_path: Path) -> None:
    """`swarmhil run ... --viz save`: the bridge as its own process over Zenoh; the demo with sc02's
    thrusters stuck off over [100, 200) s, which the viewer marks on sc02 over those steps (it
    subscribes to `faults`), live and in the replay."""
    scenario = tmp_path / "demo-fault.toml"
    scenario.write_text((SCENARIOS / "demo.toml").read_text() + '\n[[fault]]\nname = "f"\nkind = "thruster_stuck_off"\n'
                        'targets = ["sc02"]\nstart_s = 100.0\nend_s = 200.0\n')
    out = tmp_path / "mp"
    _cli_run(scenario, out, 300.0)
    rrd_verify(out / "run.rrd")
    assert check_positions_equal_truth(out / "run.rrd", out / "run.mcap") == 31
    check_scene(out / "run.rrd", out / "run.mcap")
    rep = replay_verified(out / "run.mcap", tmp_path / "replay.rrd")
    check_same_views(out / "run.rrd", rep)
    check_scene(rep, out / "run.mcap")
    truth = mcap_truth(out / "run.mcap")
    for rrd in (out / "run.rrd", rep):
        faulty = read_rrd(rrd)["/world/faulty"]["Points3D:positions"]
        marked = {s: [tuple(p) for p in v] for s, v in faulty.items() if len(v)}
        expect = {s: [tuple(truth[s][1][truth[s][0].index("sc02")].astype(np.float32))] for s in range(10, 20)}
        assert marked == expect, sorted(marked)


def test_p000_capture_with_viz_save_and_replay(tmp_path: Path) -> None:
    """Paper 000 (capture-10 in-process for 3 s; agent a0 turned to face the target and the landmark
    sensor's range R_l raised from 8.5 to 15 m, so that it sees the target from the start as agents
    do from 21.7 s in the scenario): agents with attitude, the tumbling target, sensor cones,
    landmark returns and the chase colour, in the live .rrd and in the replay of its recording."""
    import re

    from scipy.spatial.transform import Rotation

    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    text = (SCENARIOS / "capture-10.toml").read_text()
    a0 = np.array([float(v) for v in re.search(r'id = "a0".*?position_m = \[(.*?)\]', text, re.S).group(1).split(",")])
    # body +x onto the line of sight a0 -> target (at the origin): the shortest rotation
    look = -a0 / np.linalg.norm(a0)
    axis = np.cross([1.0, 0.0, 0.0], look)
    q = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.arccos(look[0])).as_quat(scalar_first=True)
    text = re.sub(r'(id = "a0".*?attitude_q = )\[.*?\]', lambda m: m.group(1) + str(q.tolist()), text, count=1, flags=re.S)
    (tmp_path / "capture.toml").write_text(text)
    sc = load_scenario(tmp_path / "capture.toml", ("sensing.params.range_m=15.0",)).with_overrides(duration_s=3.0)
    out = tmp_path / "p000"
    run_in_process(sc, out, "viz-p000", opts={"viz": "save"})
    rrd_verify(out / "run.rrd")
    rep = replay_verified(out / "run.mcap", tmp_path / "replay.rrd")
    for rrd in (out / "run.rrd", rep):
        check_scene(rrd, out / "run.mcap", camera=False)
        rows = read_rrd(rrd)
        returns = [len(p) for sid in mcap_truth(out / "run.mcap")[0][0]
                   for p in rows[f"/world/sc/{sid}/landmarks"]["Points3D:positions"].values()]
        assert sum(returns) > 0                             # some agent sees the target
        last = rows["/world/swarm"]["Points3D:colors"]
        chase = MODE_COLOURS["chase"]
        assert any(((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255) == chase for c in last[max(last)])
        assert rows["/world/sc/a0/sensor"]["LineStrips3D:strips"][-1]
        q = rows["/world/targets/target"]["Transform3D:quaternion"]
        assert q[max(q)] != q[min(q)]                      # the target tumbles
        check_returns_on_the_surface(rows, "a0", semi_axes=(2.6, 1.9, 1.4))
    check_same_views(out / "run.rrd", rep)


def check_returns_on_the_surface(rows: dict, sid: str, semi_axes: tuple[float, float, float]) -> None:
    """The inlier returns, drawn in the agent's frame, land on the target's ellipsoid placed by the
    target's frame: the agent's and the target's drawn attitudes agree with the sensor's frames."""
    from scipy.spatial.transform import Rotation

    from swarmhil.dashboards.rerun_bridge import LANDMARK_COLOUR

    sc_tf, tg_tf = rows[f"/world/sc/{sid}"], rows["/world/targets/target"]
    lm = rows[f"/world/sc/{sid}/landmarks"]
    green = (LANDMARK_COLOUR[0] << 24) | (LANDMARK_COLOUR[1] << 16) | (LANDMARK_COLOUR[2] << 8) | 255
    checked = 0
    for step, pts in lm["Points3D:positions"].items():
        inl = np.array([p for p, c in zip(pts, lm["Points3D:colors"][step]) if c == green]).reshape(-1, 3)
        if not len(inl):
            continue
        world = np.array(sc_tf["Transform3D:translation"][step][0]) + Rotation.from_quat(sc_tf["Transform3D:quaternion"][step][0]).apply(inl)
        body = Rotation.from_quat(tg_tf["Transform3D:quaternion"][step][0]).inv().apply(world - np.array(tg_tf["Transform3D:translation"][step][0]))
        f = np.sqrt(((body / np.array(semi_axes)) ** 2).sum(axis=1))
        assert np.all(np.abs(f - 1.0) < 0.05), (step, f)    # 2 cm noise on a 1.4-2.6 m ellipsoid
        checked += len(inl)
    assert checked > 0


@pytest.mark.system
def test_sabatini_20_with_viz_save(tmp_path: Path) -> None:
    """The issue's acceptance run: sabatini-20 (20 agents, behavioural control) with --viz save."""
    out = tmp_path / "sab"
    _cli_run(SCENARIOS / "sabatini-20.toml", out, 3600.0)
    rrd_verify(out / "run.rrd")
    n = check_positions_equal_truth(out / "run.rrd", out / "run.mcap")
    assert n == 361
    rows = read_rrd(out / "run.rrd")
    assert len(rows["/world/estimates"]["Points3D:positions"]) > 300   # the agents' beliefs are drawn
    check_scene(out / "run.rrd", out / "run.mcap")
    rep = replay_verified(out / "run.mcap", tmp_path / "replay.rrd")
    check_same_views(out / "run.rrd", rep)
    check_scene(rep, out / "run.mcap")


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
def test_connect_mode_streams_to_a_running_server(tmp_path: Path) -> None:
    """`--viz connect URL`: a `rerun --serve-grpc` on 127.0.0.1 (saving what it gets) receives the views."""
    import os
    import signal
    import socket
    import time

    from swarmhil.dashboards.viz_node import free_port
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    disable_analytics()
    port = free_port()
    received = tmp_path / "received.rrd"
    srv = subprocess.Popen([rerun_exe(), "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port), "--save", str(received)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                           preexec_fn=sigint_default)
    try:
        t_end = time.monotonic() + 60
        listening = False
        while not listening:
            assert srv.poll() is None, f"rerun --serve-grpc exited with code {srv.returncode} before listening"
            assert time.monotonic() < t_end, f"rerun --serve-grpc did not listen on 127.0.0.1:{port} within 60 s"
            with socket.socket() as s:
                listening = s.connect_ex(("127.0.0.1", port)) == 0
            if not listening:
                time.sleep(0.1)
        sc = load_scenario(SCENARIOS / "demo.toml").with_overrides(duration_s=200.0)
        # the viz node's close flushes the recording stream (blocking) and disconnects the gRPC sink,
        # which closes its stream only once the server has taken everything: no sleep is needed
        res = run_in_process(sc, tmp_path / "run", "viz-connect",
                             opts={"viz": "connect", "viz_url": f"rerun+http://127.0.0.1:{port}/proxy"})
        assert res.summary["viz"]["samples"]["truth"] == sc.steps + 1
    finally:
        os.kill(srv.pid, signal.SIGINT)   # by PID: the server started here
        try:
            srv.wait(120)  # it writes its .rrd on the way out: over 30 s once on a loaded 2-core machine
        except subprocess.TimeoutExpired:
            os.kill(srv.pid, signal.SIGKILL)
            srv.wait()
            raise
    got = read_rrd(received)["/world/swarm"]["Points3D:positions"]
    sent = read_rrd(tmp_path / "run" / "run.rrd")["/world/swarm"]["Points3D:positions"]
    assert sorted(sent) == list(range(21)), sorted(sent)  # the local copy holds every step of 200 s
    missing = sorted(set(sent) - set(got))
    assert not missing, f"the server did not receive steps {missing} of {sorted(sent)}"
    assert got == sent
