"""A test's own `@pytest.mark.timeout(N)` wins over the per-test default of pyproject.toml (issue 24).

pytest-timeout takes the marker first, then --timeout, then the ini's `timeout`; tests that need
longer than the default 600 s (tests/test_system_camera.py: 645 s measured) say so with the marker.
Shown here with this project's own configuration (`-c pyproject.toml`: its addopts, markers and
timeout method), the default lowered to 1 s so that it takes seconds: a test sleeping 2 s passes
under its own 10 s marker and is stopped without one.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import ROOT

SYNTHETIC = '''
import time

import pytest


@pytest.mark.timeout(10)
def test_own_timeout_is_longer():
    time.sleep(2)


def test_default_timeout():
    time.sleep(2)
'''


def test_a_tests_own_timeout_marker_wins_over_the_default(tmp_path: Path) -> None:
    (tmp_path / "test_synthetic.py").write_text(SYNTHETIC)
    r = subprocess.run([sys.executable, "-m", "pytest", "-c", str(ROOT / "pyproject.toml"), "--rootdir", str(tmp_path),
                        "-p", "no:cacheprovider", "-o", "timeout=1", "-q", str(tmp_path / "test_synthetic.py")],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    out = r.stdout + r.stderr
    assert "1 failed, 1 passed" in out, out
    assert any(line.startswith("FAILED test_synthetic.py::test_default_timeout") for line in out.splitlines()), out
    assert "Failed: Timeout (>1.0s) from pytest-timeout" in out, out
