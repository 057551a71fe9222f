"""Shared fixtures: repository paths, scenario writing, MCAP reading without the project's code."""
from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

SCENARIOS = ROOT / "deploy" / "scenarios"


def pytest_runtest_setup(item: pytest.Item) -> None:
    """A `browser` test needs Chromium and playwright-core (`make setup-system`): checked before its
    fixtures run (a failure in CI, a skip with the install command elsewhere; tests/system_tools.py)."""
    if item.get_closest_marker("browser"):
        from system_tools import require_chromium, require_playwright_core

        require_chromium()
        require_playwright_core()


def sigint_default() -> None:
    """preexec_fn for a child a test stops with SIGINT: a shell that runs `make test` in the
    background starts it with SIGINT ignored, and children inherit that (the Ctrl-C test then
    waited 60 s for a launcher that never saw the signal)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def root() -> Path:
    return ROOT


def read_mcap(path: Path | str):
    """Decode every message with the standard readers only: [(topic, log_time, publish_time, msg)]."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    out = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            out.append((channel.topic, message.log_time, message.publish_time, decoded))
    return out
