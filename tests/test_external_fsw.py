"""External flight software (issue 26, docs/hil.md): a spacecraft with `fsw = "external"` is flown by
a process the launcher does not start, here examples/external_fsw/fc.py, which imports nothing of
the project. Real processes over real Zenoh on loopback; recordings read with the standard readers.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS, read_mcap
from deploy.scenario import ScenarioError, load_scenario, parse_scenario

SCENARIO = SCENARIOS / "hil-3.toml"
SWARMHIL = [sys.executable, "-m", "deploy.cli"]
FC = ROOT / "examples" / "external_fsw"


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except OSError:
        return False


def _started_pids(out: Path) -> list[int]:
    return [p for pids in json.loads((out / "run.json").read_text())["all_pids"].values() for p in pids]


def test_external_spacecraft_is_validated() -> None:
    sc = load_scenario(SCENARIO)
    from deploy.external import external_ids, join_timeout_s, plant_ready_timeout_s

    assert external_ids(sc) == ["sc02"] and join_timeout_s(sc, "sc02") == 300.0
    assert plant_ready_timeout_s(sc.with_overrides()) == 600.0
    assert sc.resolved()["spacecraft"][1]["fsw"] == "external"  # the recording says who flew it
    doc = tomllib.loads(SCENARIO.read_text())
    bad = json.loads(json.dumps(doc))
    bad["spacecraft"][1]["fsw"] = "elsewhere"
    with pytest.raises(ScenarioError, match=r"x.toml: \[\[spacecraft\]\]\[1\].fsw .*'builtin' or 'external'"):
        parse_scenario(bad, "x.toml")
    bad = json.loads(json.dumps(doc))
    bad["spacecraft"][0]["join_timeout_s"] = 5.0
    with pytest.raises(ScenarioError, match=r"\[\[spacecraft\]\]\[0\] .*join_timeout_s applies to fsw = \"external\" only"):
        parse_scenario(bad, "x.toml")
    long = json.loads(json.dumps(doc))
    long["spacecraft"][1]["join_timeout_s"] = 3600.0
    assert plant_ready_timeout_s(parse_scenario(long, "x.toml")) == 3660.0  # the plant outwaits the launcher


def test_in_process_run_refuses_an_external_spacecraft(tmp_path: Path) -> None:
    r = subprocess.run([*SWARMHIL, "run", str(SCENARIO), "--in-process", "--out", str(tmp_path / "r")],
                       capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=120)
    assert r.returncode == 2, r
    assert r.stderr.strip().count("\n") == 0 and "sc02 fly external flight software" in r.stderr, r.stderr


def test_join_timeout_is_one_line_and_leaves_nothing_running(tmp_path: Path) -> None:
    """Nobody joins: the launcher prints where the kit is and what it waits for, then, after the
    join timeout, one line naming the spacecraft and the endpoint; exit 1; every process it
    started is gone."""
    out = tmp_path / "run"
    r = subprocess.run([*SWARMHIL, "run", str(SCENARIO), "--out", str(out), "--run-id", "jt", "--no-progress",
                        "--set", "spacecraft.1.join_timeout_s=2"],
                       capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=180)
    assert r.returncode == 1, (r.stdout, r.stderr)
    router = json.loads((out / "run.json").read_text())["router"]
    assert r.stdout.splitlines() == [
        f"waiting up to 2 s for the external flight software of sc02 to join at {router} (liveliness token "
        f"swarm/jt/alive/agent-sc02); its join kit: {out}/external/sc02/join.json"], r.stdout
    assert r.stderr.splitlines() == [
        f"error: external flight software of spacecraft sc02 did not join within 2 s: no liveliness token "
        f"swarm/jt/alive/agent-sc02 at {router}"], r.stderr
    pids = _started_pids(out)
    assert len(pids) == 5 and not [p for p in pids if _alive(p)]  # router, recorder, plant, sc01, sc03
    kit = out / "external" / "sc02"
    assert sorted(p.name for p in kit.iterdir()) == ["agent-sc02.cred", "join.json", "keys.json", "swarmhil.proto"]
    assert (kit / "swarmhil.proto").read_bytes() == (ROOT / "bus" / "swarmhil.proto").read_bytes()
    assert all(p.stat().st_mode & 0o077 == 0 for p in [kit, *kit.iterdir()])  # it holds a secret
    doc = json.loads((kit / "join.json").read_text())
    assert doc["router"] == [router] and doc["run"] == "jt" and doc["process"] == "agent-sc02"
    assert doc["keys"]["act"] == "swarm/jt/sc/sc02/act" and doc["message_types"]["sense"] == "swarmhil.v1.RelStimulus"
    assert doc["zenoh"]["transport/auth/usrpwd/password"] == (kit / "agent-sc02.cred").read_text().strip().split(":")[1]
    assert doc["timing"]["deadline"]["mode"] == "lockstep" and doc["agent"]["controller"] == "drift-null"
