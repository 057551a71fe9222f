"""The Rerun logger of the viewer bridge (dashboards/rerun_bridge.py) on messages made here.

Independent references: the plant's visibility rule (plant/sensors.py) for the camera digraph,
scipy's weak components for connectivity, the flight software's ROE map for believed positions;
values are read back from the .rrd with Rerun's own reader.
"""
from __future__ import annotations

import io

import numpy as np
import pytest
import rerun as rr

from agent.roe import roe_to_lvlh
from bus import swarmhil_pb2 as pb
from bus.codec import vec
from bus.keys import Keys
from dashboards.replay import read_rrd
from dashboards.rerun_bridge import (DEAD_COLOUR, MODE_COLOURS, CameraRule, Paths, SwarmLogger, mode_colour,
                                     visibility, weak_components)
from plant.sensors import CameraGeometry, visibility_matrix

RUN = "viztest"
K = Keys(RUN)
A_M = 6878137.0
N_RADPS = float(np.sqrt(3.986004418e14 / A_M**3))
STEP_S = 10.0


def test_visibility_matches_the_plant_rule() -> None:
    rng = np.random.default_rng(1)
    rule, cam = CameraRule(), CameraGeometry()
    for _ in range(50):
        pos = rng.normal(scale=[60.0, 300.0, 60.0], size=(12, 3))
        alive = rng.random(12) > 0.2
        np.testing.assert_array_equal(visibility(pos, alive, rule), visibility_matrix(pos, cam, alive))
    # batched over steps gives the same as one step at a time
    pos = rng.normal(scale=[60.0, 300.0, 60.0], size=(5, 12, 3))
    alive = np.ones((5, 12), bool)
    batch = visibility(pos, alive, rule)
    for s in range(5):
        np.testing.assert_array_equal(batch[s], visibility_matrix(pos[s], cam, alive[s]))


def test_camera_rule_from_scenario_is_half_image_over_focal() -> None:
    rule = CameraRule.from_scenario({"detection_range_m": 300.0, "image_px": 1080, "focal_px": 1000.0})
    assert rule.detection_range_m == 300.0 and rule.tan_half_fov == pytest.approx(0.54)


def test_weak_components_match_scipy() -> None:
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(2)
    vis = rng.random((40, 15, 15)) < 0.08
    alive = rng.random((40, 15)) > 0.15
    got = weak_components(vis, alive)
    for s in range(40):
        idx = np.flatnonzero(alive[s])
        sub = vis[s][np.ix_(idx, idx)]
        want = connected_components(sub, directed=True, connection="weak")[0] if len(idx) else 0
        assert got[s] == want


def test_unknown_modes_get_a_stable_colour() -> None:
    assert mode_colour("coast") == MODE_COLOURS["coast"]
    assert mode_colour("something-new") == mode_colour("something-new")
    assert mode_colour("attraction_disabled") != MODE_COLOURS["attraction"]


# --- a small synthetic run -----------------------------------------------------------------------
IDS = ["a1", "a2", "a3", "a4"]
ROE_M = np.array([[0, 0, 0, 0, 0, 0], [0, 150, 10, -5, 8, 3], [2, 320, -6, 4, -5, 7], [0, -900, 0, 0, 0, 0]], float)


def _u(step: int) -> float:
    return N_RADPS * step * STEP_S


def positions(step: int) -> np.ndarray:
    return roe_to_lvlh(ROE_M, _u(step), N_RADPS)[0]


def hdr(source: str, step: int) -> pb.Header:
    return pb.Header(run=RUN, source=source, step=step, t=step * STEP_S)


def truth(step: int, dead: set[str] = frozenset()) -> bytes:
    pos = positions(step)
    msg = pb.Truth(header=hdr("plant", step), u_rad=_u(step), semi_major_axis_m=A_M, mean_motion_radps=N_RADPS)
    for i, sid in enumerate(IDS):
        msg.bodies.append(pb.BodyState(id=sid, kind="spacecraft", position_m=vec(pos[i]), alive=sid not in dead,
                                       delta_v_mps=0.001 * step * (i + 1)))
    msg.bodies.append(pb.BodyState(id="tgt", kind="target", position_m=vec([5.0, 50.0, 0.0]), alive=True))
    return msg.SerializeToString()


def telemetry(sid: str, step: int, mode: str) -> bytes:
    tm = pb.Telemetry(header=hdr(sid, step), mode=mode, controller="test")
    i = IDS.index(sid)
    for j, nb in enumerate(IDS):
        if j != i and j < 3 and i < 3:
            tm.decisions.append(pb.NeighbourDecision(neighbour=nb, behaviour="alignment",
                                                     roe_rel_m=(ROE_M[j] - ROE_M[i]).tolist()))
    return tm.SerializeToString()


def png_bytes() -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 6), (200, 30, 30)).save(buf, format="PNG")
    return buf.getvalue()


@pytest.fixture(scope="module")
def logged(tmp_path_factory: pytest.TempPathFactory) -> dict:
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    path = tmp_path_factory.mktemp("viz") / "synthetic.rrd"
    rec = rr.RecordingStream("swarmhil", recording_id="synthetic")
    rec.set_sinks(rr.FileSink(str(path)))
    lg = SwarmLogger(rec, RUN, trail_steps=30, step_s=STEP_S)
    ev = pb.Event(header=hdr("plant", 3), kind="agent_dead", subject="a4", detail="test")
    for step in range(6):
        # telemetry of a step comes before its truth, except a3's of step 2, which comes after truth 2
        # and after a flush (in lockstep every telemetry of step k comes before truth k+1)
        for sid in IDS[:3]:
            if (sid, step) != ("a3", 2):
                lg.ingest(K.tm(sid), telemetry(sid, step, "coast" if step < 2 else "attraction"))
        if step == 3:
            lg.ingest(K.tm("a3"), telemetry("a3", 2, "attraction"))
        if step == 1:
            pkt = pb.IslPacket(header=hdr("channel", 1), src="a1", dst="a2", type="beacon")
            lg.ingest(K.isl_rx("a2"), pkt.SerializeToString())
            img = CompressedImage(format="png", data=png_bytes())
            img.timestamp.seconds = 10
            lg.ingest(f"{K.base}/sc/a1/tm/image", img.SerializeToString())
        if step == 3:
            lg.ingest(K.event, ev.SerializeToString())
            st = pb.LinkStats(header=hdr("channel", 3), tx_messages=5, rx_messages=4,
                              links=[pb.LinkCounter(src="a1", dst="a2", messages=4, payload_bytes=40, wire_bytes=90)])
            lg.ingest(K.link_stats, st.SerializeToString())
        lg.ingest(K.truth, truth(step, dead={"a4"} if step >= 3 else set()))
        lg.ingest(K.truth.replace(RUN, "otherrun"), b"")     # another run's key: rejected
        if step in (1, 2, 3):
            lg.flush()
    bad = pb.Truth(header=pb.Header(run="otherrun", step=9)).SerializeToString()
    lg.ingest(K.truth, bad)                                  # foreign header.run: rejected
    lg.flush(final=True)
    rec.flush()
    rec.disconnect()
    return {"rows": read_rrd(path), "logger": lg, "path": path}


def latest_at(rows: dict[int, object], t: int) -> object:
    ts = [s for s in rows if s <= t]
    return rows[max(ts)] if ts else None


def test_positions_are_the_truth_in_float32(logged: dict) -> None:
    rows = logged["rows"]["/world/swarm"]
    assert rows["Points3D:labels"][-1] == IDS
    for step in range(6):
        got = np.array(rows["Points3D:positions"][step])
        np.testing.assert_array_equal(got, positions(step).astype(np.float32))
    trails = logged["rows"]["/world/trails"]["Points3D:positions"]
    assert sorted(trails) == list(range(6))


def test_visibility_segments_and_connectivity(logged: dict) -> None:
    rows = logged["rows"]
    for step in range(6):
        alive = np.array([True, True, True, step < 3])
        vis = visibility_matrix(positions(step), CameraGeometry(), alive)
        strips = rows["/world/visibility"]["LineStrips3D:strips"][step]
        want = {(tuple(np.float32(positions(step)[j])), tuple(np.float32(positions(step)[k]))) for j, k in zip(*np.nonzero(vis))}
        assert {(tuple(np.float32(s[0])), tuple(np.float32(s[1]))) for s in strips} == want
        from scipy.sparse.csgraph import connected_components

        idx = np.flatnonzero(alive)
        n_wcc = connected_components(vis[np.ix_(idx, idx)], directed=True, connection="weak")[0]
        assert rows["/" + Paths.WCC]["Scalars:scalars"][step] == [n_wcc]
        assert rows["/" + Paths.DV_TOTAL]["Scalars:scalars"][step] == [pytest.approx(0.001 * step * 10)]


def test_colours_follow_modes_deaths_and_late_telemetry(logged: dict) -> None:
    colours = logged["rows"]["/world/swarm"]["Points3D:colors"]

    def rgb(step: int) -> list[tuple[int, int, int]]:
        packed = latest_at(colours, step)
        return [((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255) for c in packed]

    coast, attr, idle = MODE_COLOURS["coast"], MODE_COLOURS["attraction"], MODE_COLOURS["idle"]
    assert rgb(1) == [coast, coast, coast, idle]            # a4 never sends telemetry
    assert rgb(2) == [attr, attr, attr, idle]                # a3's late telemetry of step 2 still counts
    assert rgb(3) == [attr, attr, attr, DEAD_COLOUR]         # a4 dead from step 3 (truth)


def test_estimates_from_decisions_sit_on_the_true_neighbours(logged: dict) -> None:
    est = logged["rows"]["/world/estimates"]
    err = logged["rows"]["/world/estimates/error"]
    for step in range(6):
        pts = np.array(est["Points3D:positions"][step])
        assert len(pts) == 6                                 # a1..a3 each about the two others
        # exact relative ROE -> the linear map puts each estimate on the neighbour's true position
        truth_pts = positions(step)[:3].astype(np.float32)
        for p in pts:
            assert np.min(np.linalg.norm(truth_pts - p, axis=1)) < 1e-2
        for a, b in err["LineStrips3D:strips"][step]:
            assert np.linalg.norm(np.subtract(a, b)) < 1e-2
    assert est["Points3D:labels"][0][0] == "a1>a2"


def test_links_are_short_lived_and_stats_events_images_logged(logged: dict) -> None:
    rows = logged["rows"]
    links = rows["/world/links"]["LineStrips3D:strips"]
    p = positions(1).astype(np.float32)
    assert [[tuple(v) for v in s] for s in links[1]] == [[tuple(p[0]), tuple(p[1])]]
    assert links[0] == [] and links[2] == []
    assert rows["/link/messages/tx"]["Scalars:scalars"][3] == [5.0]
    assert rows["/link/bytes/wire"]["Scalars:scalars"][3] == [90.0]
    assert rows["/events"]["TextLog:text"][3] == ["agent_dead a4: test"]
    assert rows["/events"]["TextLog:level"][3] == ["ERROR"]
    assert rows["/world/targets/tgt"]["Points3D:positions"][2] == [[5.0, 50.0, 0.0]]
    img = rows["/cameras/a1"]
    assert img["EncodedImage:media_type"][1] == ["image/png"]
    assert bytes(img["EncodedImage:blob"][1][0]) == png_bytes()


def test_foreign_samples_are_rejected_not_logged(logged: dict) -> None:
    lg = logged["logger"]
    assert lg.rejections.total == 6 + 1      # six foreign keys, one foreign header.run
    assert 9 not in logged["rows"]["/world/swarm"]["Points3D:positions"]


def test_rrd_passes_rerun_verify(logged: dict) -> None:
    import subprocess

    from dashboards.viz_node import disable_analytics, rerun_exe

    disable_analytics()
    r = subprocess.run([rerun_exe(), "rrd", "verify", str(logged["path"])], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_blueprint_has_3d_view_time_series_and_log() -> None:
    from dashboards.rerun_bridge import blueprint

    def views(part: object) -> list[object]:
        import rerun.blueprint as rrb

        return [v for c in part.contents for v in views(c)] if isinstance(part, rrb.Container) else [part]

    kinds = [type(v).__name__ for v in views(blueprint(100, 10.0, cameras=["a1"]).root_container)]
    assert kinds.count("Spatial3DView") == 1 and kinds.count("TextLogView") == 1
    assert kinds.count("TimeSeriesView") == 4 and kinds.count("Spatial2DView") == 1
    assert "Spatial2DView" not in [type(v).__name__ for v in views(blueprint(100, 10.0).root_container)]
