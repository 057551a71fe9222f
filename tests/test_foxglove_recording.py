"""The MCAP contract as a Foxglove user meets it (DESIGN.md "MCAP (contract)", issue 18).

Recordings are read with the `mcap` reader and the `mcap-protobuf-support` decoder alone (the
schemas come from the file): topics without `swarm/<run>/`, log_time = epoch + simulation time,
publish_time the reception wall time, and Foxglove's own FrameTransforms / SceneUpdate for every
body at every step. The shipped layout references only topics that exist.
"""
from __future__ import annotations

import json
import re
import time
from datetime import datetime, timezone
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS

EPOCH = "2030-03-20T06:00:00.5Z"
EPOCH_NS = int(datetime(2030, 3, 20, 6, 0, 0, tzinfo=timezone.utc).timestamp()) * 10**9 + 500_000_000


def _decoded(path: Path):
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        msgs = [(ch.topic, s.name, m.log_time, m.publish_time, d) for s, ch, m, d in reader.iter_decoded_messages()]
    return meta, msgs


@pytest.fixture(scope="module")
def surround(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """surround-6 (six spacecraft and a spheres-shaped target) for 20 steps, in process."""
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario

    d = tmp_path_factory.mktemp("fox")
    text = (SCENARIOS / "surround-6.toml").read_text()
    text = re.sub(r"(?m)^duration_s = 300\.0", "duration_s = 2.0", text, count=1)
    text = text.replace("[run]\n", f'[run]\nepoch_utc = "{EPOCH}"\n', 1)
    scen = d / "surround-short.toml"
    scen.write_text(text)
    sc = load_scenario(scen)
    assert sc.resolved()["run"]["epoch_utc"] == "2030-03-20T06:00:00.500000Z"
    res = run_in_process(sc, d / "run", "fox-surround")
    assert res.exit_code == 0, res.reason
    return d / "run" / "run.mcap"


def test_frames_and_scene_of_every_body_at_every_step_on_the_simulated_timeline(surround: Path) -> None:
    meta, msgs = _decoded(surround)
    assert meta["swarmhil.run"]["run"] == "fox-surround"
    cfg = json.loads(meta["swarmhil.config"]["json"])
    target = next(b for b in cfg["body"] if b["id"] == "tsat")
    assert not any(t.startswith("swarm/") for t, *_ in msgs)
    truth = {int(d.header.step): (lt, d) for t, s, lt, _p, d in msgs if t == "truth"}
    tfs = [(lt, d) for t, s, lt, _p, d in msgs if t == "foxglove/tf" and s == "foxglove.FrameTransforms"]
    scenes = [(lt, d) for t, s, lt, _p, d in msgs if t == "foxglove/scene" and s == "foxglove.SceneUpdate"]
    assert len(truth) == 21 and len(tfs) == len(scenes) == len(truth)
    tf_at = {lt: d for lt, d in tfs}
    scene_at = {lt: d for lt, d in scenes}
    for step, (lt, tr) in sorted(truth.items()):
        assert lt == EPOCH_NS + round(tr.header.t * 1e9), step
        ids = {b.id for b in tr.bodies}
        assert len(ids) == 8 and "tsat" in ids  # leader, six followers, the target
        tf = tf_at[lt]
        frames = {x.child_frame_id: x for x in tf.transforms}
        assert set(frames) == ids and {x.parent_frame_id for x in tf.transforms} == {"lvlh"}
        for b in tr.bodies:
            x = frames[b.id]
            assert (x.translation.x, x.translation.y, x.translation.z) == (b.position_m.x, b.position_m.y, b.position_m.z)
            assert x.timestamp.seconds * 10**9 + x.timestamp.nanos == lt
            q = x.rotation
            assert abs(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z - 1.0) < 1e-9
        ents = {e.id: e for e in scene_at[lt].entities}
        assert ids <= set(ents) and "links" in ents
        for b in tr.bodies:
            assert ents[b.id].frame_id == b.id and ents[b.id].spheres
        # the target drawn from its [[body]].shape: one sphere per structure sphere, diameter 2 r
        assert [s.size.x for s in ents["tsat"].spheres] == pytest.approx([2 * r for r in target["shape"]["radii_m"]])
    # every other sample: log_time on the same timeline, publish_time = reception wall time
    now = time.time_ns()
    for t, s, lt, pub, d in msgs:
        assert lt >= EPOCH_NS and 0 < now - pub < 600 * 10**9, t
        if s.startswith("swarmhil.v1.") and d.HasField("header") and d.header.run:
            assert lt == EPOCH_NS + round(d.header.t * 1e9), t
    logs = [d for t, s, _l, _p, d in msgs if t == "foxglove/log"]
    assert logs and len(logs) == sum(1 for t, *_ in msgs if t == "event")


def test_attitude_is_the_frame_rotation_identity_otherwise(tmp_path: Path) -> None:
    from swarmhil.bus import swarmhil_pb2 as pb
    from swarmhil.bus.recorder import McapRecorder

    r = McapRecorder(tmp_path / "a.mcap", "att", config={"body": [{"id": "t", "shape": {"kind": "ellipsoid",
                                                                                        "semi_axes_m": [1, 2, 3]}}]})
    q = pb.Quaternion(w=0.5, x=0.5, y=0.5, z=0.5)
    tr = pb.Truth(header=pb.Header(run="att", source="plant", step=3, t=30.0),
                  bodies=[pb.BodyState(id="a", kind="spacecraft", alive=True, attitude=q),
                          pb.BodyState(id="t", kind="target")])
    r.write("swarm/att/truth", tr.SerializeToString())
    r.write("swarm/att/sc/a/act", b"\xff\xff\xff")  # undecodable: keeps the last simulation time
    r.close()
    _meta, msgs = _decoded(tmp_path / "a.mcap")
    epoch = 946728000 * 10**9  # default epoch 2000-01-01T12:00:00Z
    assert {t: lt for t, _s, lt, _p, _d in msgs} == {"truth": epoch + 30 * 10**9, "foxglove/tf": epoch + 30 * 10**9,
                                                     "foxglove/scene": epoch + 30 * 10**9,
                                                     "sc/a/act": epoch + 30 * 10**9}
    tf = next(d for t, _s, _l, _p, d in msgs if t == "foxglove/tf")
    rot = {x.child_frame_id: (x.rotation.w, x.rotation.x, x.rotation.y, x.rotation.z) for x in tf.transforms}
    assert rot == {"a": (0.5, 0.5, 0.5, 0.5), "t": (1.0, 0.0, 0.0, 0.0)}
    scene = next(d for t, _s, _l, _p, d in msgs if t == "foxglove/scene")
    ell = next(e for e in scene.entities if e.id == "t").spheres[0].size
    assert (ell.x, ell.y, ell.z) == (2.0, 4.0, 6.0)


def test_epoch_is_validated() -> None:
    from swarmhil.deploy.scenario import ScenarioError, parse_scenario

    doc = {"run": {"name": "x", "epoch_utc": "2024-02-30T00:00:00Z"}, "spacecraft": [{"id": "a", "roe_m": [0] * 6}]}
    with pytest.raises(ScenarioError, match=r"\[run\].epoch_utc"):
        parse_scenario(doc, "x.toml")
    doc["run"]["epoch_utc"] = "2024-02-03T01:00:00+01:00"
    assert parse_scenario(doc, "x.toml").epoch_utc == "2024-02-03T00:00:00Z"
    del doc["run"]["epoch_utc"]
    assert parse_scenario(doc, "x.toml").resolved()["run"]["epoch_utc"] == "2000-01-01T12:00:00Z"


def _layout_topics(layout: dict) -> set[str]:
    topics: set[str] = set()
    for panel, cfg in layout["configById"].items():
        kind = panel.split("!")[0]
        if kind == "3D":
            topics |= set(cfg["topics"])
        elif kind == "Plot":
            topics |= {p["value"].split(".", 1)[0].strip('"') for p in cfg["paths"]}
        elif kind == "Log":
            topics.add(cfg["topicToRender"])
        elif kind == "RawMessages":
            topics.add(cfg["topicPath"].split(".", 1)[0].strip('"'))
    return topics


def test_shipped_layout_references_only_topics_that_exist(surround: Path) -> None:
    layout = json.loads((ROOT / "dashboards" / "foxglove" / "swarmhil-layout.json").read_text())
    used = _layout_topics(layout)
    assert {"foxglove/tf", "foxglove/scene", "truth", "foxglove/log", "event"} <= used
    _meta, msgs = _decoded(surround)
    assert used <= {t for t, *_ in msgs}
    frames = {x.child_frame_id for t, _s, _l, _p, d in msgs if t == "foxglove/tf" for x in d.transforms} | {"lvlh"}
    assert layout["configById"]["3D!swarm"]["followTf"] in frames


def _as_old_recording(src: Path, dst: Path, run: str) -> None:
    """The same messages with the pre-contract topics `swarm/<run>/...` and no metadata."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as fin, open(dst, "wb") as fout:
        reader = make_reader(fin)
        w = Writer(fout, compression=CompressionType.ZSTD)
        w.start(profile="", library="old")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, ch, m in reader.iter_messages(log_time_order=False):
            if ch.topic.startswith("foxglove/"):
                continue
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if ch.id not in channels:
                channels[ch.id] = w.register_channel(f"swarm/{run}/{ch.topic}", ch.message_encoding, schemas[schema.id])
            w.add_message(channels[ch.id], m.publish_time, m.data, m.log_time, m.sequence)
        w.finish()


def test_readers_accept_old_prefixed_topics(surround: Path, tmp_path: Path) -> None:
    from swarmhil.dashboards.replay import run_id_of
    from swarmhil.dashboards.truth_io import read_truth

    old = tmp_path / "old" / "run.mcap"
    old.parent.mkdir()
    _as_old_recording(surround, old, "fox-surround")
    a, b = read_truth(surround), read_truth(old)
    assert a.run == b.run == "fox-surround"
    assert a.ids == b.ids and (a.position_m == b.position_m).all() and (a.t_s == b.t_s).all()
    assert run_id_of(surround) == run_id_of(old) == "fox-surround"


def test_spacecraft_spheres_take_their_agents_mode_colour(tmp_path: Path) -> None:
    """The scene colours a spacecraft by the mode of its newest telemetry (the viewer's colours),
    blue before any, grey once dead."""
    from swarmhil.bus import swarmhil_pb2 as pb
    from swarmhil.bus.foxglove_scene import MODE_COLOURS
    from swarmhil.bus.recorder import McapRecorder

    r = McapRecorder(tmp_path / "m.mcap", "mode")

    def truth(step: int, alive: bool = True) -> bytes:
        return pb.Truth(header=pb.Header(run="mode", source="plant", step=step, t=float(step)),
                        bodies=[pb.BodyState(id="a", kind="spacecraft", alive=alive)]).SerializeToString()

    r.write("swarm/mode/truth", truth(0))
    r.write("swarm/mode/sc/a/tm", pb.Telemetry(header=pb.Header(run="mode", source="a", step=0), mode="chase").SerializeToString())
    r.write("swarm/mode/truth", truth(1))
    r.write("swarm/mode/truth", truth(2, alive=False))
    r.close()
    _meta, msgs = _decoded(tmp_path / "m.mcap")
    colours = [next(e for e in d.entities if e.id == "a").spheres[0].color for t, _s, _l, _p, d in msgs if t == "foxglove/scene"]
    rgb = [(round(c.r * 255), round(c.g * 255), round(c.b * 255)) for c in colours]
    assert rgb[1] == MODE_COLOURS["chase"] and rgb[0] != rgb[1] and rgb[2] not in (rgb[0], rgb[1])


def test_scene_bytes_are_those_of_the_entities_built_field_by_field(surround: Path) -> None:
    """FoxgloveScene.from_truth writes the frame transforms as bytes (each FrameTransform's fields
    in number order) and SceneUpdate's entities as bytes (a serialised template after
    the timestamp): the bytes are exactly those protobuf gives the message built field by field (each
    body's template, then its timestamp; the `links` entity last), at time 0 (an empty timestamp) and
    later, with ISL links and agent modes."""
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from mcap.reader import make_reader

    from swarmhil.bus import swarmhil_pb2 as pb
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.Vector3_pb2 import Vector3

    from foxglove_schemas_protobuf.Color_pb2 import Color
    from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
    from foxglove_schemas_protobuf.Point3_pb2 import Point3
    from foxglove_schemas_protobuf.Pose_pb2 import Pose
    from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion

    from swarmhil.bus.foxglove_scene import FoxgloveScene, _rotation, _timestamp

    with open(surround, "rb") as f:
        reader = make_reader(f)
        cfg = next(json.loads(m.metadata["json"]) for m in reader.iter_metadata() if m.name == "swarmhil.config")
    with open(surround, "rb") as f:
        truths = [pb.Truth.FromString(m.data) for _s, _c, m in make_reader(f).iter_messages(topics=["truth"])]
    scene = FoxgloveScene(cfg)
    ids = [b.id for b in truths[0].bodies]
    assert len(truths) > 3 and len(ids) > 2
    for k, truth in enumerate(truths):
        t_ns = k * 1_500_000_000
        pairs = [(ids[0], ids[1]), (ids[2], ids[0]), (ids[1], ids[2]), (ids[0], "gone")][:k % 5] if k % 2 else []
        for src, dst in pairs:
            scene.saw_delivery(src, dst)
        scene._modes[ids[k % len(ids)]] = ("chase", "dock", "")[k % 3]
        tf_data, data = scene.from_truth(truth, t_ns)
        tf = FrameTransforms()  # the transforms built field by field
        for b in truth.bodies:
            q = b.position_m
            tf.transforms.add(timestamp=_timestamp(t_ns), parent_frame_id="lvlh", child_frame_id=b.id,
                              translation=Vector3(x=q.x, y=q.y, z=q.z),
                              rotation=_rotation(b, truth.mean_motion_radps, truth.header.t))
        assert tf_data == tf.SerializeToString()
        built = SceneUpdate()
        for b in truth.bodies:
            ent = built.entities.add()
            ent.CopyFrom(scene._template(b.id, b.kind, b.alive))
            ent.timestamp.CopyFrom(_timestamp(t_ns))
        parsed = SceneUpdate.FromString(data)
        assert parsed.entities[-1].id == "links" and bool(parsed.entities[-1].lines) == bool(pairs)
        links = built.entities.add(timestamp=_timestamp(t_ns), frame_id="lvlh", id="links", frame_locked=False)
        pos = {b.id: b.position_m for b in truth.bodies}
        line = LinePrimitive(type=LinePrimitive.LINE_LIST, pose=Pose(orientation=Quaternion(w=1.0)), thickness=1.5,
                             scale_invariant=True, color=Color(r=0.3, g=1.0, b=0.4, a=0.8))
        for src, dst in sorted(set(pairs)):  # (the links known to the truth's bodies, their ends' positions)
            if src in pos and dst in pos:
                for q in (pos[src], pos[dst]):
                    line.points.append(Point3(x=q.x, y=q.y, z=q.z))
        if line.points:
            links.lines.append(line)
        assert data == built.SerializeToString() == parsed.SerializeToString()
        if k == 3:  # (a body at the origin: its point's coordinates are omitted, +0.0)
            assert any(p.x == p.y == p.z == 0.0 for p in parsed.entities[-1].lines[0].points)
