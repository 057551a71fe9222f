"""The Rerun logger of the viewer bridge (dashboards/rerun_bridge.py) on messages made here.

Independent references: the plant's visibility rule (plant/sensors.py) for the camera digraph,
scipy's weak components for connectivity, the flight software's ROE map for believed positions,
scipy's rotations for attitudes, the camera model (agent/camera/model.py) for the camera mount;
values are read back from the .rrd with Rerun's own reader, blueprints counted by `rerun rrd print`.
"""
from __future__ import annotations

import json

import io

import numpy as np
import pytest
import rerun as rr

from swarmhil.agent.roe import roe_to_lvlh
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import vec
from swarmhil.bus.keys import Keys
from swarmhil.dashboards.replay import read_rrd
from swarmhil.dashboards.rerun_bridge import DEAD_COLOUR, MODE_COLOURS, CameraRule, Paths, SwarmLogger, mode_colour
from swarmhil.plant.sensors import CameraGeometry, visibility_matrix

RUN = "viztest"
K = Keys(RUN)
A_M = 6878137.0
N_RADPS = float(np.sqrt(3.986004418e14 / A_M**3))
STEP_S = 10.0


# the viewer's visibility and component count are the plant's (plant/sensors.py): tests/test_visibility_once.py
def test_camera_rule_from_scenario_is_half_image_over_focal() -> None:
    rule = CameraRule.from_scenario({"detection_range_m": 300.0, "image_px": 1080, "focal_px": 1000.0})
    assert rule.detection_range_m == 300.0 and rule.tan_half_fov == pytest.approx(0.54)


def test_unknown_modes_get_a_stable_colour() -> None:
    assert mode_colour("coast") == MODE_COLOURS["coast"]
    assert mode_colour("something-new") == mode_colour("something-new")
    assert mode_colour("attraction_disabled") != MODE_COLOURS["attraction"]


# --- a small synthetic run -----------------------------------------------------------------------
IDS = ["a1", "a2", "a3", "a4"]
ROE_M = np.array([[0, 0, 0, 0, 0, 0], [0, 150, 10, -5, 8, 3], [2, 320, -6, 4, -5, 7], [0, -900, 0, 0, 0, 0]], float)
Q_A1_INERTIAL = np.array([0.8, 0.2, -0.4, 0.4]) / np.linalg.norm([0.8, 0.2, -0.4, 0.4])   # a1 flies attitude (wxyz)
TARGET_AXES = [3.0, 2.0, 1.0]
# the resolved configuration the logger reads (deploy/scenario.py resolved(): only the keys it uses)
CONFIG = {"sensing": {"kind": "scene"}, "camera": {"detection_range_m": 500.0, "image_px": 1080, "focal_px": 1000.0},
          "nav": {"debug_image_period_s": 10.0, "debug_image_downsample": 4}, "actuator": {"max_accel_mps2": 1e-3},
          "spacecraft": [{"id": s, "mass_kg": 10.0} for s in IDS],
          "body": [{"id": "tgt", "kind": "target", "shape": {"kind": "ellipsoid", "semi_axes_m": TARGET_AXES}}]}


def accel(step: int, i: int) -> list[float]:
    return [1e-4 * (i + 1), -2e-4 * step, 5e-5]


def target_q(step: int) -> list[float]:
    """A spinning target, scalar first: about z at 0.1 rad a step."""
    return [float(np.cos(0.05 * step)), 0.0, 0.0, float(np.sin(0.05 * step))]


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
        b = pb.BodyState(id=sid, kind="spacecraft", position_m=vec(pos[i]), alive=sid not in dead,
                         delta_v_mps=0.001 * step * (i + 1), accel_cmd_mps2=vec(accel(step, i)))
        if sid == "a1":
            b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z = Q_A1_INERTIAL.tolist()
        msg.bodies.append(b)
    w, x, y, z = target_q(step)
    msg.bodies.append(pb.BodyState(id="tgt", kind="target", position_m=vec([5.0, 50.0, 0.0]), alive=True,
                                   attitude=pb.Quaternion(w=w, x=x, y=y, z=z)))
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
    lg = SwarmLogger(rec, RUN, trail_steps=30, step_s=STEP_S, config=CONFIG)
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
        if step in (2, 4):  # a2's thrusters stuck off over steps [2, 4) (plant/node.py's faults events)
            fault = json.dumps({"name": "f0", "kind": "thruster_stuck_off", "targets": ["a2"], "start_s": 2 * STEP_S,
                                "end_s": 4 * STEP_S})
            lg.ingest(K.faults, pb.Event(header=hdr("plant", step), kind="fault_start" if step == 2 else "fault_end",
                                         subject="f0", detail=fault).SerializeToString())
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
    assert rows["/world/targets/tgt"]["Transform3D:translation"][2] == [[5.0, 50.0, 0.0]]
    img = rows["/world/sc/a1/camera/image"]
    assert img["EncodedImage:media_type"][1] == ["image/png"]
    assert bytes(img["EncodedImage:blob"][1][0]) == png_bytes()


def test_a_struck_spacecraft_is_marked_while_its_fault_lasts(logged: dict) -> None:
    rows = logged["rows"]
    faulty = rows["/world/faulty"]
    a2 = IDS.index("a2")
    assert {s: [tuple(p) for p in faulty["Points3D:positions"][s]] for s in range(2, 6)} == {
        2: [tuple(positions(2)[a2].astype(np.float32))], 3: [tuple(positions(3)[a2].astype(np.float32))], 4: [], 5: []}
    assert faulty["Points3D:labels"][3] == ["thruster_stuck_off"]
    assert rows["/events"]["TextLog:text"][2][0].startswith("fault_start f0: {")
    assert rows["/events"]["TextLog:level"][4] == ["WARN"]


def test_foreign_samples_are_rejected_not_logged(logged: dict) -> None:
    lg = logged["logger"]
    assert lg.rejections.total == 6 + 1      # six foreign keys, one foreign header.run
    assert 9 not in logged["rows"]["/world/swarm"]["Points3D:positions"]


def test_rrd_passes_rerun_verify(logged: dict) -> None:
    import subprocess

    from swarmhil.dashboards.viz_node import disable_analytics, rerun_exe

    disable_analytics()
    r = subprocess.run([rerun_exe(), "rrd", "verify", str(logged["path"])], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_blueprint_has_3d_view_time_series_and_log() -> None:
    from swarmhil.dashboards.rerun_bridge import blueprint

    def views(part: object) -> list[object]:
        import rerun.blueprint as rrb

        return [v for c in part.contents for v in views(c)] if isinstance(part, rrb.Container) else [part]

    kinds = [type(v).__name__ for v in views(blueprint(100, 10.0, cameras=["a1"]).root_container)]
    assert kinds.count("Spatial3DView") == 1 and kinds.count("TextLogView") == 1
    assert kinds.count("TimeSeriesView") == 5 and kinds.count("Spatial2DView") == 1
    assert "Spatial2DView" not in [type(v).__name__ for v in views(blueprint(100, 10.0).root_container)]


def blueprints_in(path: object) -> int:
    """Blueprints sent into a .rrd: `rerun rrd print` lists one activation command per blueprint."""
    import subprocess

    from swarmhil.dashboards.viz_node import disable_analytics, rerun_exe

    disable_analytics()
    r = subprocess.run([rerun_exe(), "rrd", "print", str(path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout.count("BlueprintActivationCommand(")


def test_blueprint_is_sent_once(logged: dict) -> None:
    assert blueprints_in(logged["path"]) == 1 and logged["logger"].blueprints_sent == 1


def test_spacecraft_frames_hold_truth_position_and_attitude_in_lvlh(logged: dict) -> None:
    """world/sc/<id>: translation = truth; rotation = body -> LVLH: a1's body -> inertial attitude
    turned by the n t the LVLH frame has rotated since t = 0 (scipy), identity for the others."""
    from scipy.spatial.transform import Rotation

    rows = logged["rows"]
    for i, sid in enumerate(IDS):
        tf = rows[f"/world/sc/{sid}"]
        assert tf["TransformAxes3D:axis_length"][-1][0] > 0
        for step in range(6):
            np.testing.assert_array_equal(np.array(tf["Transform3D:translation"][step][0]), positions(step)[i].astype(np.float32))
            q = np.array(tf["Transform3D:quaternion"][step][0])          # xyzw
            if sid == "a1":
                want = (Rotation.from_euler("z", -N_RADPS * step * STEP_S)
                        * Rotation.from_quat(Q_A1_INERTIAL, scalar_first=True)).as_matrix()
            else:
                want = np.eye(3)
            np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), want, atol=1e-6)
            assert rows[f"/metrics/delta_v_by_spacecraft/{sid}"]["Scalars:scalars"][step] == [pytest.approx(0.001 * step * (i + 1))]


def test_cameras_are_pinholes_on_the_paper_002_mount(logged: dict) -> None:
    """A pinhole per spacecraft, sized as the debug frames (1080 px / 4, f = 1000 / 4), mounted so
    that the camera frame maps to LVLH as the flight software's camera model says."""
    from swarmhil.agent.camera.model import R_LVLH_FROM_CAM

    rows = logged["rows"]
    for sid in IDS:
        cam = rows[f"/world/sc/{sid}/camera"]
        np.testing.assert_allclose(np.array(cam["Pinhole:image_from_camera"][-1][0]).reshape(3, 3).T,
                                   [[250.0, 0, 135.0], [0, 250.0, 135.0], [0, 0, 1]])
        assert cam["Pinhole:resolution"][-1] == [[270.0, 270.0]]
        np.testing.assert_array_equal(np.array(cam["Transform3D:mat3x3"][-1][0]).reshape(3, 3).T, R_LVLH_FROM_CAM)


def test_thrust_arrows_are_the_applied_acceleration(logged: dict) -> None:
    rows = logged["rows"]["/world/thrust"]
    lg = logged["logger"]
    scale = lg._thrust_scale
    assert scale == pytest.approx(lg._lengths["thrust_m"] / 1e-3)   # the [actuator] limit is full length
    for step in range(6):
        np.testing.assert_allclose(np.array(rows["Arrows3D:vectors"][step]),
                                   np.array([accel(step, i) for i in range(4)]) * scale, rtol=1e-6)
        np.testing.assert_array_equal(np.array(rows["Arrows3D:origins"][step]), positions(step).astype(np.float32))


def test_target_rotates_with_its_shape(logged: dict) -> None:
    rows = logged["rows"]
    tf = rows["/world/targets/tgt"]
    for step in range(6):
        w, x, y, z = target_q(step)
        np.testing.assert_allclose(tf["Transform3D:quaternion"][step][0], [x, y, z, w], atol=1e-7)
    assert rows["/world/targets/tgt/shape"]["Ellipsoids3D:half_sizes"][-1] == [TARGET_AXES]


def test_p000_sensor_cone_and_landmark_returns(tmp_path) -> None:
    """Paper 000's configuration: a cone about body +x out to R_l, the returns of each step in the
    body frame (outliers red), agents coloured by mode, no camera."""
    from pathlib import Path

    from swarmhil.dashboards.rerun_bridge import LANDMARK_COLOUR, OUTLIER_COLOUR
    from swarmhil.deploy.scenario import load_scenario

    cfg = load_scenario(Path(__file__).resolve().parent.parent / "deploy" / "scenarios" / "capture-10.toml").resolved()
    path = tmp_path / "p000.rrd"
    rec = rr.RecordingStream("swarmhil", recording_id="p000")
    rec.set_sinks(rr.FileSink(str(path)))
    lg = SwarmLogger(rec, RUN, trail_steps=10, step_s=0.05, config=cfg)
    for step in range(4):
        lg.ingest(K.tm("a0"), pb.Telemetry(header=hdr("a0", step), mode="search" if step < 2 else "chase").SerializeToString())
        t = pb.Truth(header=pb.Header(run=RUN, source="plant", step=step, t=0.05 * step), mean_motion_radps=1.1e-3)
        t.bodies.add(id="a0", kind="spacecraft", alive=True, position_m=vec([5.0, 0.0, 0.0]),
                     attitude=pb.Quaternion(w=1.0))
        t.bodies.add(id="target", kind="target", alive=True, attitude=pb.Quaternion(w=1.0))
        lg.ingest(K.truth, t.SerializeToString())
        m = pb.Measurements(header=pb.Header(run=RUN, source="plant", step=step, t=0.05 * step))
        pts = [[1.0, 0.1 * step, 0.0], [2.0, 0.0, 0.5]] if step != 1 else []
        m.items.add(name="p000_landmarks_body_m", values=np.ravel(pts).tolist(), shape=[len(pts), 3])
        m.items.add(name="p000_landmark_ids", values=[7.0, -1.0][:len(pts)])
        lg.ingest(K.sense("a0", "p000-landmarks"), m.SerializeToString())
    lg.flush(final=True)
    rec.flush()
    rec.disconnect()
    rows = read_rrd(path)
    cone = rows["/world/sc/a0/sensor"]["LineStrips3D:strips"][-1]
    rim = np.array(cone[0])
    assert np.allclose(np.linalg.norm(rim, axis=1), 8.5, rtol=1e-5)             # R_l
    assert np.allclose(np.degrees(np.arccos(rim[:, 0] / 8.5)), 37.5, atol=1e-3)   # half of the 75 deg cone
    lm = rows["/world/sc/a0/landmarks"]
    np.testing.assert_allclose(lm["Points3D:positions"][2], [[1.0, 0.2, 0.0], [2.0, 0.0, 0.5]], rtol=1e-6)
    assert lm["Points3D:positions"][1] == []
    rgb = [((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255) for c in lm["Points3D:colors"][2]]
    assert rgb == [LANDMARK_COLOUR, OUTLIER_COLOUR]
    assert "/world/sc/a0/camera" not in rows
    np.testing.assert_allclose(rows["/world/targets/target/shape"]["Ellipsoids3D:half_sizes"][-1], [[2.6, 1.9, 1.4]], rtol=1e-6)
    colours = rows["/world/swarm"]["Points3D:colors"]
    chase = [((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255) for c in latest_at(colours, 3)]
    assert chase == [MODE_COLOURS["chase"]] and latest_at(colours, 0) != latest_at(colours, 3)
