"""The bandwidth report (dashboards/bandwidth/) and `swarmhil report-bandwidth`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import read_mcap

SCENARIO = """
[run]
name = "{name}"
duration_s = 200.0
step_s = 10.0
seed = 5

[controller]
name = "null"

[dispersion]
count = 4
sigma_roe_m = [20.0, 40.0, 30.0, 30.0, 30.0, 30.0]
along_track_spacing_m = 150.0

[link]
range_m = 250.0
loss_probability = 0.1
overhead_bytes = 16
bitrate_bps = 20.0
queue_packets = 1
stats_period_s = 30.0

[beacon]
period_s = {period}
"""


def _run(tmp: Path, name: str, period: float) -> Path:
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    p = tmp / f"{name}.toml"
    p.write_text(SCENARIO.format(name=name, period=period))
    run_in_process(load_scenario(p), tmp / name, name)
    return tmp / name


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("bw")
    return _run(d, "every10", 10.0), _run(d, "every20", 20.0)


def test_report_of_one_run(runs: tuple[Path, Path]) -> None:
    from swarmhil.dashboards.bandwidth.accounting import consistency, link_matrix, per_agent_series
    from swarmhil.dashboards.bandwidth.page import write_bandwidth_report
    from swarmhil.dashboards.bandwidth.read import read_link_traffic

    run = runs[0]
    lt = read_link_traffic(run)
    checks = consistency(lt)
    assert all(ok for *_x, ok in checks), checks
    tot = {c[0]: c for c in checks}
    # a 20 bit/s radio cannot send a 16 B + beacon every 10 s: the queue drops, and the counters say so
    assert tot["dropped_queue"][2] > 0 and tot["dropped_range"][2] > 0 and tot["dropped_lost"][2] > 0
    # the link matrix and the time series account for every delivered byte of the recording
    rx = [m for t, _l, _p, m in read_mcap(run / "run.mcap") if t.startswith("isl/rx/")]
    wire = sum(len(m.payload) + 16 for m in rx)
    assert link_matrix(lt).sum() == wire == tot["rx_wire_bytes"][1]
    s = per_agent_series(lt, 30.0)
    assert s["rx_bytes"].sum() == wire and s["tx_msgs"].sum() == tot["tx_messages"][1]
    assert np.all(np.diag(link_matrix(lt)) == 0)
    html = write_bandwidth_report(run)
    text = html.read_text()
    assert html == run / "report" / "bandwidth.html"
    assert "Per link and message type" in text and "NO</span>" not in text
    for png in ("per_agent", "rate", "matrix", "drops"):
        assert (html.parent / f"bandwidth_{png}.png").read_bytes()[:4] == b"\x89PNG"


def test_comparison_mode(runs: tuple[Path, Path], tmp_path: Path) -> None:
    from swarmhil.dashboards.bandwidth.accounting import totals
    from swarmhil.dashboards.bandwidth.page import write_bandwidth_comparison
    from swarmhil.dashboards.bandwidth.read import read_link_traffic

    a, b = runs
    out = write_bandwidth_comparison(a, b, tmp_path / "cmp" / "compare.html")
    text = out.read_text()
    assert "every10" in text and "every20" in text
    for png in ("bandwidth_compare.png", "bandwidth_compare_matrix.png"):
        assert png in text  # the page shows it
        w, h = _png_size(tmp_path / "cmp" / png)
        assert w > 300 and h > 200, (png, w, h)  # a real figure, not an empty or broken file
    ta, tb = totals(read_link_traffic(a))["mcap"], totals(read_link_traffic(b))["mcap"]
    assert ta["tx_messages"] == 4 * 20 and tb["tx_messages"] == 4 * 10  # half the beacons
    # the page's numbers are the recordings': each run's transmissions appear in it
    for t in (ta, tb):
        assert f">{t['tx_messages']}<" in text, t['tx_messages']


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; fails on anything that is not a PNG."""
    import struct

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR", path
    return struct.unpack(">II", data[16:24])


def test_cli_and_disagreement_detection(runs: tuple[Path, Path], tmp_path: Path) -> None:
    import shutil

    from swarmhil.deploy.cli_bandwidth import report_bandwidth

    res = CliRunner().invoke(report_bandwidth, [str(runs[0])])
    assert res.exit_code == 0, res.output
    assert "transmissions" in res.output
    res = CliRunner().invoke(report_bandwidth, [str(runs[0]), "--compare", str(runs[1]), "--out", str(tmp_path / "c.html")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "c.html").read_text()
    assert "every10" in page and "every20" in page and "bandwidth_compare.png" in page
    # a channel whose counters do not match the recording is reported, with exit code 1
    bad = tmp_path / "bad"
    shutil.copytree(runs[0], bad)
    s = json.loads((bad / "summary.json").read_text())
    s["channel"]["totals"]["rx_wire_bytes"] += 1
    (bad / "summary.json").write_text(json.dumps(s))
    res = CliRunner().invoke(report_bandwidth, [str(bad)])
    assert res.exit_code == 1 and "rx_wire_bytes" in res.output and "DISAGREE" in res.output


def test_subcommand_is_registered() -> None:
    from swarmhil.deploy.cli import main

    assert "report-bandwidth" in main.commands
