"""The report site (dashboards/site.py), its figures, its tables and swarmhil.load (issue 18).

- Windows and titles come from the run: a 20-minute run and a 24 h run of the same swarm are
  reported, and the texts of the page and of the SVG figures (text kept as text) are checked
  against windows computed here from the recorded truth.
- Figure defects: the digraph's titles fit and do not overlap, counts get whole-number ticks, the
  PNGs are at 150 dpi or more.
- The site: every page linked from index.html, plotly.js once as a file of the site (no CDN), the
  tables of data/ identical in Parquet and CSV.
- `swarmhil.load` gives back every recorded Truth value exactly (compared with the raw messages of
  the plain mcap reader), and the code of docs/analysis.md runs.
"""
from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import read_mcap

ROOT = Path(__file__).resolve().parent.parent
SITE_SCENARIO = ROOT / "tests" / "data" / "site-20min.toml"

TINY = """
[run]
name = "tiny-{name}"
duration_s = {duration}
step_s = {step}
seed = 3

[controller]
name = "drift-null"
[controller.params]
gain_per_s = 1e-3

[sensing]
roe_noise_fraction = 0.0

[[spacecraft]]
id = "a"
roe_m = [10.0, -300.0, 20.0, 0.0, 20.0, 0.0]

[[spacecraft]]
id = "b"
roe_m = [-5.0, -150.0, 0.0, 25.0, 0.0, 25.0]

[[spacecraft]]
id = "c"
roe_m = [0.0, 0.0, -15.0, 15.0, -15.0, 15.0]
"""


def _tiny(tmp: Path, name: str, duration: float, step: float) -> Path:
    from swarmhil.dashboards.report import write_report
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    p = tmp / f"{name}.toml"
    p.write_text(TINY.format(name=name, duration=duration, step=step))
    run_in_process(load_scenario(p), tmp / name, f"tiny-{name}", progress=False)
    write_report(tmp / name, interactive=False, export=("svg",))
    return tmp / name


@pytest.fixture(scope="module")
def short_and_long(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("windows")
    return _tiny(d, "20min", 1200.0, 10.0), _tiny(d, "24h", 86400.0, 60.0)


@pytest.fixture(scope="module")
def site_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 20-minute run with every kind of page, reported with `swarmhil report` (the CLI)."""
    from swarmhil.deploy.cli import main
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    out = tmp_path_factory.mktemp("site") / "run"
    run_in_process(load_scenario(SITE_SCENARIO), out, "site-20min", progress=False)
    res = CliRunner().invoke(main, ["report", str(out)])
    assert res.exit_code == 0, res.output
    return out


def _svg_texts(path: Path) -> list[str]:
    import html

    return [html.unescape(t) for t in re.findall(r"<text[^>]*>([^<]*)</text>", path.read_text())]


def test_windows_and_titles_follow_the_run(short_and_long: tuple[Path, Path]) -> None:
    from swarmhil.dashboards.truth_io import read_truth

    for run, long in zip(short_and_long, (False, True)):
        tr = read_truth(run / "run.mcap")
        run_s = tr.t_s[-1] - tr.t_s[0]
        assert run_s == (86400.0 if long else 1200.0)
        page = (run / "report" / "index.html").read_text()
        proj = " ".join(_svg_texts(run / "report" / "projections.svg"))
        dv = _svg_texts(run / "report" / "dv.svg")
        three_orbits_h = 3 * 2 * math.pi / tr.mean_motion_radps / 3600.0
        if long:
            # 24 h: Fig. 22 shows the last three orbits (about 4.7 h at 500 km), dV "over the last 1 h"
            assert f"last {three_orbits_h:.3g} h, 3 orbits" in proj, proj
            assert "over the last 1 h" in page and "24 h (1441 steps)" in page
            assert "time [h]" in dv
        else:
            # 20 min: shorter than both windows, so the whole run, said so; minutes on the axes
            assert "whole run, 20 min" in proj and "last" not in proj, proj
            assert "over the whole run, 20 min" in page and "in the last hour" not in page
            assert "last 1 h" not in page and "20 min (121 steps)" in page
            assert "time [min]" in dv and "time [h]" not in dv
        # the orbit-union line of Fig. 10 says what it is when the run is shorter than an orbit
        comp = " ".join(_svg_texts(run / "report" / "components.svg"))
        assert ("over the last orbit" in comp) if long else ("since the start (run shorter than the" in comp), comp
        # the steady window (last sixth) is written in the run's own units
        assert ("t &gt;= 20 h" in page) if long else ("t &gt;= 16.7 min" in page), page[:3000]


def test_figures_fit_count_in_integers_and_are_150_dpi(short_and_long: tuple[Path, Path]) -> None:
    from swarmhil.dashboards.figstyle import draw_static, overflowing_texts
    from swarmhil.dashboards.metrics import compute_metrics
    from swarmhil.dashboards.truth_io import read_truth
    from swarmhil.missions.p002_sabatini.report.figures import draw_digraph, spec_components
    from swarmhil.missions.p002_sabatini.report.metrics import NAME

    run = short_and_long[1]
    tr = read_truth(run / "run.mcap")
    m = compute_metrics(tr).missions[NAME].detail  # paper 002's series (its metrics hook)
    fig = draw_digraph(tr, m, len(tr.t_s) - 1, "end")
    assert overflowing_texts(fig) == []
    fig = draw_static(spec_components(m, len(tr.ids)))
    for ax in fig.axes:
        ticks = [t for t in ax.get_yticks() if ax.get_ylim()[0] <= t <= ax.get_ylim()[1]]
        assert ticks and all(float(t).is_integer() for t in ticks), ticks
    assert overflowing_texts(fig) == []
    # the SVG says the same: component counts 0, 1, 2, 3 on the axis, no 0.5 or 2.5
    texts = _svg_texts(run / "report" / "components.svg")
    assert {"0", "1", "2", "3"} <= set(texts) and not {"0.5", "1.5", "2.5"} & set(texts)
    for png in (run / "report").glob("*.png"):
        data = png.read_bytes()
        i = data.index(b"pHYs")
        ppm_x, ppm_y, unit = struct.unpack(">IIB", data[i + 4:i + 13])
        assert unit == 1 and ppm_x * 0.0254 >= 149.9, (png.name, ppm_x * 0.0254)


def test_site_links_every_page_and_writes_the_tables(site_run: Path) -> None:
    import pandas as pd

    rep = site_run / "report"
    index = (rep / "index.html").read_text()
    pages = ["index.html", "navigation.html", "bandwidth.html", "events.html", "data.html"]
    for p in pages:
        text = (rep / p).read_text()
        for q in pages:  # the bar of links on every page
            assert f'href="{q}"' in text, (p, q)
        assert not re.search(r"<script[^>]+src=\"https?:", text), p  # nothing from a CDN
        for src in re.findall(r'(?:src|href)="([^"#:]+)"', text):
            assert (rep / src).is_file(), (p, src)  # every local link resolves
    # `swarmhil report` (default --vector) saves every figure as SVG and PDF beside its PNG: the other
    # report tests pass --no-vector, so this is where the vector copies are checked
    pngs = sorted(rep.glob("*.png"))
    assert len(pngs) >= 10 and not [p.name for p in pngs if not (p.with_suffix(".svg").stat().st_size > 1000
                                                               and p.with_suffix(".pdf").stat().st_size > 1000)]
    assert index.count('<script src="plotly.min.js">') == 1 and (rep / "plotly.min.js").stat().st_size > 1_000_000
    assert index.count('class="plotly-graph-div"') >= 10
    for name in ("truth", "commands", "link", "link_totals", "events", "metrics_series", "metrics"):
        a = pd.read_parquet(rep / "data" / f"{name}.parquet")
        b = pd.read_csv(rep / "data" / f"{name}.csv", keep_default_na=False, na_values=[""])
        assert len(a) == len(b) > 0, name
        for col in a.columns:
            if a[col].dtype.kind == "f":
                np.testing.assert_array_equal(a[col].to_numpy(), b[col].to_numpy(dtype=float), err_msg=f"{name}.{col}")
    truth = pd.read_parquet(rep / "data" / "truth.parquet")
    assert sorted(truth["id"].unique()) == [f"sc{i:02d}" for i in range(1, 7)] and truth["step"].nunique() == 121
    # the event page lists every event of the recording, in its order, read here from the MCAP
    import html as html_mod
    from collections import Counter

    want = [(f"{m.header.t:.6g}", str(m.header.step), m.header.source, m.kind, m.subject, m.detail)
            for topic, _l, _p, m in read_mcap(site_run / "run.mcap") if topic == "event"]
    kinds = Counter(w[3] for w in want)
    assert kinds["run_start"] == 1 and kinds["link_config"] == 1, kinds  # the plant's and the link's
    events = (rep / "events.html").read_text()
    rows = [tuple(html_mod.unescape(c) for c in re.findall(r"<td>(.*?)</td>", r, re.S))
            for r in re.findall(r"<tr>(<td>.*?)</tr>", events, re.S)]
    assert rows == want
    counts = ", ".join(f"{k}: {n}" for k, n in sorted(kinds.items()))
    assert f"{len(want)} events from the recording's <code>event</code> topic ({counts})." in events


def test_load_round_trips_the_truth_exactly(site_run: Path) -> None:
    import swarmhil

    run = swarmhil.load(site_run)
    first: dict[int, object] = {}
    for topic, _lt, _pt, m in read_mcap(site_run / "run.mcap"):
        if topic == "truth":
            first.setdefault(int(m.header.step), m)
    rows = [(k, m, b) for k, m in sorted(first.items()) for b in m.bodies]
    t = run.truth
    assert len(t) == len(rows)
    cols = {c: t[c].to_numpy() for c in t.columns}
    for r, (k, m, b) in enumerate(rows):
        assert cols["step"][r] == k and cols["t_s"][r] == m.header.t and cols["id"][r] == b.id
        got = [cols[c][r] for c in ("x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps", "ax_cmd_mps2", "ay_cmd_mps2",
                                    "az_cmd_mps2", "delta_v_mps", "u_rad", "semi_major_axis_m", "mean_motion_radps")]
        want = [b.position_m.x, b.position_m.y, b.position_m.z, b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z,
                b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z, b.delta_v_mps, m.u_rad,
                m.semi_major_axis_m, m.mean_motion_radps]
        assert got == want, (k, b.id)  # exact: the same doubles
        assert [cols[c][r] for c in ("roe_da_m", "roe_dl_m", "roe_dex_m", "roe_dey_m", "roe_dix_m", "roe_diy_m")] \
            == list(b.roe_m)
        assert bool(cols["alive"][r]) == b.alive
    # the Parquet table the report wrote is the same frame, bit for bit
    import pandas as pd

    pd.testing.assert_frame_equal(pd.read_parquet(site_run / "report" / "data" / "truth.parquet"), t,
                                  check_exact=True)
    # the other tables: commands of every spacecraft and step, link counters, metrics
    assert set(run.commands["id"]) == set(t["id"]) and len(run.commands) == 6 * 120
    assert len(run.link) > 0 and (run.link["dst"] == "*").any() and len(run.events) > 0
    assert run.metrics_series["t_s"].tolist() == sorted(t["t_s"].unique().tolist())
    assert run.config["controller"]["name"] == "sabatini"


def test_analysis_doc_runs(site_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every python block of docs/analysis.md, in order, on a real run (RUN is the run directory)."""
    import matplotlib

    matplotlib.use("Agg")
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "analysis.md").read_text(), re.S)
    assert len(blocks) >= 3
    ns: dict[str, object] = {"RUN": str(site_run)}
    for code in blocks:
        exec(compile(code.replace('"runs/demo"', "RUN"), "docs/analysis.md", "exec"), ns)  # noqa: S102
    out = capsys.readouterr().out
    assert "total dV" in out
