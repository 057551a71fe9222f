"""Paper 001's report section (issue 13): `swarmhil report RUN` on a tersoff-6 run.

The run is tersoff-6 in-process with the gathering compressed so that the whole story fits in a
short test: t_desire = 3000 s, t_natural = 2925 s, 8000 s at 5 s steps (the far layer flies the
1000 m sphere in 3000 s instead of 19,500 s, faster than the paper's 0.18 m/s; everything after
the 100 m sphere is the paper's law). Seed 1 forms the hexagon at about 4300 s. The section's
numbers are checked against values recomputed here from the MCAP with the standard reader only
(conftest.read_mcap), not through dashboards/truth_io.py.
"""
from __future__ import annotations

import json
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, SCENARIOS, read_mcap

SCENARIO = SCENARIOS / "tersoff-6.toml"
T_DESIRE_S, T_NATURAL_S, DURATION_S = 3000.0, 2925.0, 8000.0
FIGS = ["p001_paths.png", "p001_pattern.png", "p001_speed_accel.png", "p001_eq16.png"]


def _cli(*args: str) -> None:
    r = subprocess.run([sys.executable, "-m", "swarmhil.deploy.cli", *args], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr + r.stdout


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("p001report") / "run"
    _cli("run", str(SCENARIO), "--out", str(out), "--no-progress", "--in-process", "--run-id", "p001-report",
         "--duration", str(DURATION_S), "--set", f"controller.params.t_desire_s={T_DESIRE_S}",
         "--set", f"controller.params.t_natural_s={T_NATURAL_S}")
    _cli("report", str(out), "--no-vector")
    return out


def _recorded(run: Path) -> dict[str, np.ndarray]:
    t, pos, vel, acc, ids = [], [], [], [], None
    for topic, _lt, _pt, m in read_mcap(run / "run.mcap"):
        if topic != "truth":
            continue
        sc = [b for b in m.bodies if b.kind == "spacecraft"]
        ids = [b.id for b in sc]
        t.append(m.header.t)
        pos.append([[b.position_m.x, b.position_m.y, b.position_m.z] for b in sc])
        vel.append([[b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z] for b in sc])
        acc.append([[b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z] for b in sc])
    return {"t": np.array(t), "pos": np.array(pos), "vel": np.array(vel), "acc": np.array(acc), "ids": ids}


def _eq16(p: np.ndarray, side: float) -> float:
    """Eq. 16 written out again: the two closest agents of each agent, |l - r_ij| / l over 2N."""
    n = len(p)
    total = 0.0
    for i in range(n):
        d = sorted(float(np.linalg.norm(p[i] - p[j])) for j in range(n) if j != i)[:2]
        total += sum(abs(side - x) / side for x in d)
    return total / (2 * n)


def test_section_metrics_match_the_recording(run: Path) -> None:
    from swarmhil.missions.p001_lattice.contract import check_hexagon, structure_name

    met = json.loads((run / "summary.json").read_text())["metrics"]["p001-formation"]
    rec = _recorded(run)
    t, pos, vel, acc, ids = rec["t"], rec["pos"], rec["vel"], rec["acc"], rec["ids"]
    assert len(t) == int(DURATION_S / 5.0) + 1 and met["t_end_s"] == t[-1]
    # the room's parameters as recorded: the --set values and the paper's radii
    assert met["params"]["t_desire_s"] == T_DESIRE_S and met["params"]["t_natural_s"] == T_NATURAL_S
    assert (met["params"]["r_middle_m"], met["params"]["r_inner_m"], met["params"]["side_m"]) == (100.0, 15.0, 10.0)
    # gathering timeline
    r = np.linalg.norm(pos, axis=2)
    for radius, key in ((100.0, "enter_middle_s"), (15.0, "enter_inner_s")):
        for i, sid in enumerate(ids):
            inside = np.flatnonzero(r[:, i] < radius)
            assert inside.size, (sid, radius)
            assert met["gathering"][key][sid] == pytest.approx(t[inside[0]])
    assert np.allclose(met["gathering"]["release_radius_m"], 1000.0)
    # the far layer ends before t_natural: every agent crosses 100 m in the compressed ballistic arc
    assert met["gathering"]["enter_middle_span_s"][1] < T_NATURAL_S
    # speed, thrust, closest approach
    assert met["speed"]["max_mps"] == pytest.approx(np.linalg.norm(vel, axis=2).max(), rel=1e-12)
    assert met["thrust"]["max_mps2"] == pytest.approx(np.linalg.norm(acc, axis=2).max(), rel=1e-12)
    assert met["thrust"]["limit_mps2"] == 5e-3 and met["thrust"]["within_limit"]
    dmin, at = np.inf, None
    for k in range(len(t)):
        for a in range(len(ids)):
            for b in range(a + 1, len(ids)):
                d = float(np.linalg.norm(pos[k, a] - pos[k, b]))
                if d < dmin:
                    dmin, at = d, (t[k], ids[a], ids[b])
    ca = met["closest_approach"]
    assert ca["distance_m"] == pytest.approx(dmin, rel=1e-12) and (ca["t_s"], *ca["pair"]) == at
    assert dmin > 5.0  # no collision
    # final structure
    f = met["final"]
    hexa = check_hexagon(pos[-1], 10.0)
    assert f["structure"] == structure_name(pos[-1], 10.0) == "6-ring"
    assert f["is_hexagon"] and hexa.is_hexagon
    assert np.allclose(f["centre_m"], pos[-1].mean(axis=0))
    assert f["phase_deg"] == pytest.approx(hexa.phase_deg)
    assert f["max_abs_x_m"] == pytest.approx(np.abs(pos[-1, :, 0]).max())
    sides = [sorted(np.linalg.norm(pos[-1, i] - pos[-1, j]) for j in range(6) if j != i)[:2] for i in range(6)]
    assert f["side_min_m"] == pytest.approx(np.min(sides)) and f["side_max_m"] == pytest.approx(np.max(sides))
    assert 10.0 < f["side_mean_m"] < 10.1  # the wells compress TB's 10.40 m bond to ~10.04 m (docs/paper001.md)
    # eq. 16 over time
    eq = np.array([_eq16(p, 10.0) for p in pos])
    assert met["eq16"]["end"] == pytest.approx(eq[-1], rel=1e-9) == f["eq16"]
    assert met["eq16"]["min"] == pytest.approx(eq.min(), rel=1e-9)
    assert met["eq16"]["end"] < 0.0125
    # the hexagon holds from formed_s to the end, not the step before
    k0 = int(np.flatnonzero(t == met["formed_s"])[0])
    assert all(check_hexagon(p, 10.0).is_hexagon for p in pos[k0:]) and not check_hexagon(pos[k0 - 1], 10.0).is_hexagon
    assert T_DESIRE_S < met["formed_s"] < DURATION_S


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", head[16:24])


def test_figures_exist_and_are_on_the_page(run: Path) -> None:
    page = (run / "report" / "index.html").read_text()
    assert "Paper 001: formation" in page
    srcs = re.findall(r'<img src="([^"]+)"', page)
    for name in FIGS:
        p = run / "report" / name
        assert p.is_file() and p.stat().st_size > 10_000, name
        w, h = _png_size(p)
        assert 400 <= w <= 2000 and 300 <= h <= 1500, (name, w, h)
        assert name in srcs
    # a mission run shows its own section, not paper 002's figures
    assert "components.png" not in srcs


def test_section_applies_to_p001_runs_only() -> None:
    from swarmhil.dashboards.sections import sections_for

    assert "p001-formation" in [n for n, _ in sections_for({"controller": {"name": "p001-lattice"}})]
    assert "p001-formation" in [n for n, _ in sections_for({"controller": {"name": "null"},
                                                            "spacecraft": [{"id": "a", "controller": "p001-lattice"}]})]
    assert "p001-formation" not in [n for n, _ in sections_for({"controller": {"name": "sabatini"}})]
