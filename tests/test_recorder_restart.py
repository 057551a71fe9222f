"""A killed recorder is restarted into a new MCAP segment (issue 17): the run completes, the gap is
recorded (Event `recorder_restart`, metadata `swarmhil.segments`), and the segments merge into one
file the standard reader reads with every step but the gap (`swarmhil mcap merge`; the killed
segment has no footer)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from conftest import ROOT, SCENARIOS, read_mcap
from swarmhil.deploy.launcher import MultiProcessRun
from swarmhil.deploy.scenario import load_scenario
from test_restart import _no_process_left


def test_a_killed_recorder_is_restarted_into_a_segment_and_merged(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    from test_backbone_run import _Clock

    path = SCENARIOS / "demo.toml"
    sc = load_scenario(path).with_overrides(duration_s=300.0, mode="realtime", speed=10.0)
    out = tmp_path / "run"
    mp = MultiProcessRun(str(path), sc, out, "recrs", progress=False,
                         overrides={"duration": 300.0, "mode": "realtime", "speed": 10.0})
    th = threading.Thread(target=lambda: setattr(th, "res", mp.execute()), daemon=True)
    th.start()
    t_end = time.monotonic() + 120
    while not (out / "run.json").exists() and time.monotonic() < t_end:
        time.sleep(0.05)
    info = json.loads((out / "run.json").read_text())
    clock = _Clock(info["router"], "recrs", out)
    try:
        clock.wait_step(8, 240)
        os.kill(info["pids"]["recorder"], signal.SIGKILL)  # this run's recorder, by PID
    finally:
        clock.close()
    th.join(300)
    assert not th.is_alive()
    res = th.res
    assert res.exit_code == 0, res.reason
    segs = res.summary["recording_segments"]
    assert segs["files"] == ["run.000.mcap", "run.001.mcap"] and segs["merged_into"] == "run.mcap"
    assert segs["segments"][0]["truncated_tail"] and not segs["segments"][1]["truncated_tail"]
    # the merged file, with the standard reader
    msgs = read_mcap(out / "run.mcap")
    steps = sorted(int(m.header.step) for t, _l, _p, m in msgs if t == "truth")
    missing = sorted(set(range(31)) - set(steps))
    assert len(steps) == len(set(steps)) and steps[0] == 0 and steps[-1] == 30
    assert missing and missing == list(range(missing[0], missing[-1] + 1)), missing  # one gap
    # killed at step >= 8: at most about a second (one flush period, 1 step at x10) lost before the
    # kill; the restart's start-up (a few seconds, more on a loaded machine) is the rest of the gap
    assert 6 <= missing[0] and missing[-1] <= 27, missing
    ev = [m for t, _l, _p, m in msgs if t == "event" and m.kind == "recorder_restart"]
    assert len(ev) == 1 and "run.001.mcap" in ev[0].detail and ev[0].header.source == "launcher"
    assert any(m.kind == "run_end" for t, _l, _p, m in msgs if t == "event")
    with open(out / "run.mcap", "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert meta["swarmhil.run"]["run"] == "recrs" and meta["swarmhil.segment"]["index"] == "1"
    assert [s["file"] for s in json.loads(meta["swarmhil.segments"]["json"])] == ["run.000.mcap", "run.001.mcap"]
    # the command line does the same from the segments
    cli = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", "mcap", "merge", str(out / "run.000.mcap"),
                          str(out / "run.001.mcap"), str(tmp_path / "m.mcap")], cwd=ROOT, capture_output=True, text=True)
    assert cli.returncode == 0, cli.stderr
    assert json.loads(cli.stdout)["messages"] == len(msgs)
    assert len(read_mcap(tmp_path / "m.mcap")) == len(msgs)
    # no process of the run is left (the killed recorder was reaped, the restarted one stopped)
    assert len(json.loads((out / "run.json").read_text())["all_pids"]["recorder"]) == 2
    _no_process_left(out)
