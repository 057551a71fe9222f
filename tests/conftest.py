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


FOLDERS = frozenset({"agent", "plant", "bus", "link", "deploy", "dashboards", "missions", "claims"})
"""The repository's folders, installed as swarmhil.<folder> (docs/architecture.md "One installed name")."""


@pytest.fixture(autouse=True)
def _project_modules_load_under_the_namespace_only() -> object:
    """Fails the test during which a project module was loaded under a bare folder name (`dashboards`
    instead of `swarmhil.dashboards`: from the repository root both import, as two copies of one
    module). A literal module name (jinja2's PackageLoader, importlib) slips past the import
    statements tests/test_rooms.py reads; this catches it where it runs."""
    yield
    bare = sorted(m for m in sys.modules if m.split(".")[0] in FOLDERS)
    assert not bare, f"project modules loaded outside the swarmhil namespace: {bare[:8]}"


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



def topics(path: Path | str, part: str) -> list[tuple[str, bytes]]:
    """The messages of every topic that starts with or contains `/part`, serialized and sorted: two runs'
    truth (`truth`), commands (`act`) or link deliveries (`isl/rx/`) compared bit for bit."""
    return sorted((t, m.SerializeToString()) for t, _l, _p, m in read_mcap(path) if t.startswith(part) or f"/{part}" in t)

def assert_refused(ep: str, good_credential, bad: list[tuple[str, object]], monkeypatch: pytest.MonkeyPatch,
                   factor: float = 5.0, floor_ms: int = 1500) -> None:
    """Each (endpoint, credential) of `bad` (None: no credential) is refused by the router at `ep`, and the refusal
    is not a slow machine or a dead router: a refused client sees only a connect timeout (zenoh says
    "Timeout!" whether the router refused it or nobody listens), so a good credential connects to the
    same router before and after, and each bad attempt waits `factor` times the slower good connect
    (at least `floor_ms`): on a machine where the good one needs 20 ms, a 1.5 s timeout means refused."""
    import time

    import zenoh

    from swarmhil.bus import zenoh_bus
    from swarmhil.bus.zenoh_bus import ZenohBus

    def good_ms(timeout_ms: int) -> float:
        monkeypatch.setattr(zenoh_bus, "CONNECT_TIMEOUT_MS", timeout_ms)
        t0 = time.monotonic()
        ZenohBus(ep, credential=good_credential).close()
        return 1e3 * (time.monotonic() - t0)

    normal = zenoh_bus.CONNECT_TIMEOUT_MS
    try:
        timeout_ms = max(floor_ms, int(factor * good_ms(normal)))
        for bad_ep, bad_credential in bad:
            monkeypatch.setattr(zenoh_bus, "CONNECT_TIMEOUT_MS", timeout_ms)
            with pytest.raises(zenoh.ZError):
                ZenohBus(bad_ep, credential=bad_credential)
        # positive control: the router is alive and lets the good credential in well within that timeout
        took = good_ms(timeout_ms)
        assert took < timeout_ms / 2, (took, timeout_ms)
    finally:
        monkeypatch.setattr(zenoh_bus, "CONNECT_TIMEOUT_MS", normal)


def components_by_hand(n: int, edges) -> list[int]:
    """Component label (smallest member) of each of n nodes, the directed edges (j, k) taken
    undirected. Union-find, written here as the tests' own reference (not plant.sensors /
    dashboards.metrics)."""
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for j, k in edges:
        a, b = root(int(j)), root(int(k))
        parent[max(a, b)] = min(a, b)
    return [root(i) for i in range(n)]


def weakly_connected_by_hand(n: int, edges) -> bool:
    """Are n nodes one component when the directed edges (j, k) are taken undirected?"""
    return len(set(components_by_hand(n, edges))) == 1


def six_with_process_faults() -> dict:
    """sabatini-20 as a document with six spacecraft for 200 s, sc03's flight software crashing at
    50 s and sc04's paused over [100, 150) s (tests of process faults)."""
    import tomllib

    d = tomllib.loads((SCENARIOS / "sabatini-20.toml").read_text())
    d["run"]["duration_s"] = 200.0
    d["dispersion"]["count"] = 6
    d["fault"] = [{"kind": "process_crash", "targets": ["sc03"], "start_s": 50.0},
                  {"kind": "process_pause", "targets": ["sc04"], "start_s": 100.0, "end_s": 150.0}]
    return d


def checked_against_own_updates(real, nav_state, tracks_bytes, seen: dict, tally):
    """A stand-in for a navigators' `update_many` (`real`) that, at every frame, also runs a copy of
    each navigator's own `update` on the same blobs and own acceleration, and asserts that the
    navigator after the batch and its copy are the same (`nav_state`), as are their output tracks
    (`tracks_bytes`). `tally(nav, out)` counts what the frame held into `seen`, with "born" (new track
    ids) and "frames" counted here."""
    import copy

    def checked(navs, t_s, u_rad, blobs, accels):
        own = [copy.deepcopy(nav) for nav in navs]
        ids_before = [nav._next_id for nav in navs]
        expect = [nav.update(t_s, u_rad, b, a) for nav, b, a in zip(own, blobs, accels)]
        got = real(navs, t_s, u_rad, blobs, accels)
        for nav, mine, out, want, k0 in zip(navs, own, got, expect, ids_before):
            assert not isinstance(out, Exception)
            assert nav_state(nav) == nav_state(mine), t_s
            assert tracks_bytes(out) == tracks_bytes(want), t_s
            tally(nav, out)
            seen["born"] += nav._next_id - k0
        seen["frames"] += 1
        return got

    return checked
