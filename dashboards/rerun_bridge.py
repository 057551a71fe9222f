"""swarmhil samples -> Rerun: the one logger behind the live viewer bridge and the MCAP replay.

`SwarmLogger.ingest(key, payload)` takes raw samples of `swarm/<run>/**` exactly as the bus or
the MCAP file gives them and only queues them (cheap, so a bus callback never stalls);
`flush()` decodes what is queued and sends it to Rerun in column batches (`send_columns`), one
call per entity per flush rather than one `log` per message (STACK-NOTES: far faster); the
whole swarm is one entity for the same reason.

Mode colours and estimates of step k are logged once step k is complete (truth k+2 has come, or
the final flush): then every agent's telemetry of step k is in, whatever the arrival order.

Timelines: "step" (sequence, header.step) and "sim_time" (duration, header.t seconds).

Entity paths (`Paths`, the one place they are spelled), positions in metres in the LVLH frame of
the reference orbit (x radial, y along-track, z cross-track):

    world/swarm                   Points3D, one labelled point per spacecraft (truth; labels static,
                                  in the order of Truth.bodies), coloured by the agent's mode
                                  (Telemetry.mode: behaviour or controller state), dark grey once the
                                  plant counts it dead
    world/trails                  Points3D, every spacecraft each step; the blueprint shows them over
                                  a trailing visible time range (one orbit) instead of re-logging strips
    world/visibility              LineStrips3D, observer -> observed segments of the camera digraph
                                  computed from truth (range <= 500 m, square FOV tan 0.54 about +y)
    world/links                   LineStrips3D, src -> dst of the ISL deliveries stamped with that step
                                  (an empty batch on steps without any, so they are short-lived)
    world/sc/<id>                 Transform3D per step: truth position and attitude (body -> LVLH;
                                  identity where the plant flies no attitude) and body axes; under
                                  it, static in the body frame (dashboards/rerun_bodies.py):
      .../camera                  Pinhole of the paper-002 camera (frustum), .../camera/image the
                                  agent's debug frames where they are on
      .../sensor                  LineStrips3D, the paper-000 landmark sensor's cone (+x, R_l)
      .../landmarks               Points3D, that step's landmark returns (outliers red)
    world/thrust                  Arrows3D, the acceleration applied over the step, from each spacecraft
    world/targets/<id>            Transform3D (position, attitude) and a label: bodies that are not
                                  spacecraft (target, debris, ...); .../shape Ellipsoids3D of [[body]].shape
    world/estimates               Points3D, where each agent believes its neighbours are (its true
                                  position + estimated relative position: Telemetry.tracks, else the
                                  decisions' relative ROE through the linear ROE map), coloured by
                                  the behaviour it chose for each (labels "agent>neighbour")
    world/estimates/error         LineStrips3D, estimate -> true position of that neighbour
    metrics/connectivity/weakly_connected_components   Scalars (alive spacecraft only)
    metrics/delta_v/total_mps     Scalars, sum of the cumulative dV of every spacecraft
    metrics/delta_v_by_spacecraft/<id>  Scalars, cumulative dV of each spacecraft
    link/messages/{tx,rx}         Scalars, cumulative counts (LinkStats)
    link/bytes/{payload,wire}     Scalars, cumulative bytes over every link (LinkStats)
    link/dropped                  Scalars, cumulative drops of every cause (LinkStats)
    world/sc/<id>/camera/image    EncodedImage, foxglove CompressedImage frames on sc/<id>/tm/image
    events                        TextLog of Event messages (agent_dead, deadline_missed, ...) and of
                                  the `faults` topic (fault_start / fault_end, WARN)
    world/faulty                  Points3D, a magenta ring on each spacecraft a [[fault]] strikes while
                                  it lasts, labelled with its kind (docs/faults.md)

The blueprint is sent once, when the logger is made: its camera views come from the configuration.
"""
from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np
from google.protobuf.message import DecodeError

from swarmhil.agent.roe import roe_to_lvlh
from swarmhil.bus import swarmhil_pb2 as pb
from swarmhil.bus.codec import Rejections
from swarmhil.bus.foxglove_scene import MODE_COLOURS, lvlh_attitude_wxyz, mode_colour  # noqa: F401 (MODE_COLOURS: re-exported)
from swarmhil.bus.keys import Keys
from swarmhil.bus.optional import require
from swarmhil.dashboards.rerun_bodies import (
    LANDMARK_KINDS,
    R_LVLH_FROM_CAM,
    SceneSpec,
    cone_strips,
    display_lengths,
    shape_ellipsoids,
    wxyz_to_xyzw,
)
from swarmhil.plant.sensors import visibility_series, weak_components

rr = require("rerun", "the Rerun viewer (--viz, replay)")
rrb = require("rerun.blueprint", "the Rerun viewer (--viz, replay)")

APP_ID = "swarmhil"
STEP = "step"
SIM_TIME = "sim_time"

SC_RADIUS_UI = -6.0       # negative radii are UI points: visible at any zoom
TRAIL_RADIUS_UI = -1.5
ESTIMATE_RADIUS_UI = -3.0
TARGET_RADIUS_UI = -9.0
LINE_RADIUS_UI = -0.75

DEAD_COLOUR = (64, 64, 64)
TARGET_COLOUR = (255, 215, 0)
VISIBILITY_COLOUR = (170, 170, 170)
LINK_COLOUR = (0, 230, 255)
ERROR_COLOUR = (255, 80, 80)
FAULT_COLOUR = (255, 0, 200)  # a spacecraft struck by a [[fault]] while it lasts (magenta ring)
FAULT_RADIUS_UI = -11.0
THRUST_COLOUR = (255, 120, 0)
CAMERA_COLOUR = (200, 200, 255)
CONE_COLOUR = (120, 200, 255, 110)
LANDMARK_COLOUR = (80, 255, 120)
OUTLIER_COLOUR = (255, 60, 60)
SHAPE_COLOUR = (255, 215, 0, 90)
EVENT_LEVELS = {"agent_dead": "ERROR", "rejected_packet": "WARN", "deadline_missed": "WARN", "lockstep_stall": "ERROR",
                "link_stall": "ERROR", "agent_restart": "WARN", "agent_rejoin": "WARN", "recorder_restart": "WARN"}


def id_colours(n: int) -> np.ndarray:
    """n distinguishable colours (golden-angle hues), uint8 (n, 3): the trail of each spacecraft."""
    hue = (np.arange(n) * 0.618033988749895) % 1.0
    k = (np.array([5.0, 3.0, 1.0])[None, :] + hue[:, None] * 6.0) % 6.0
    rgb = 1.0 - 0.55 * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)  # HSV -> RGB with s=0.55, v=1
    return (rgb * 255).astype(np.uint8)


@dataclass(frozen=True)
class CameraRule:
    """The camera of paper 002 as the viewer knows it from a recording: range and tan of the half
    FOV (square, about +y LVLH); the rule itself is plant/sensors.py in_view (a VisibilityRule)."""

    detection_range_m: float = 500.0
    tan_half_fov: float = 0.54   # (image_px / 2) / focal_px = 540 / 1000

    @classmethod
    def from_scenario(cls, camera: dict[str, Any] | None) -> "CameraRule":
        cam = camera or {}
        image_px = float(cam.get("image_px", 1080))
        focal_px = float(cam.get("focal_px", 1000.0))
        return cls(float(cam.get("detection_range_m", 500.0)), image_px / 2.0 / focal_px)

    def as_dict(self) -> dict[str, float]:
        return {"detection_range_m": self.detection_range_m, "tan_half_fov": self.tan_half_fov}


def roe_rel_to_position_m(roe_rel_m: np.ndarray, u_rad: Any, n_radps: float) -> np.ndarray:
    """Relative LVLH positions (K, 3) of pairs from their relative ROE (K, 6) in metres at u (scalar or (K,)).

    The flight software's own linear map (agent/roe.py, D'Amico; NOTES-002): what the agent believes.
    """
    return roe_to_lvlh(np.asarray(roe_rel_m, float).reshape(-1, 6), np.asarray(u_rad, float), n_radps)[0]


@dataclass
class TruthFrame:
    step: int
    t_s: float
    u_rad: float
    n_radps: float
    ids: tuple[str, ...]          # spacecraft
    pos_m: np.ndarray             # (N, 3)
    alive: np.ndarray             # (N,)
    delta_v_mps: np.ndarray       # (N,)
    target_ids: tuple[str, ...]
    target_pos_m: np.ndarray      # (T, 3)
    att_xyzw: np.ndarray          # (N, 4) body -> LVLH (Rerun's xyzw), identity where not flown
    accel_mps2: np.ndarray        # (N, 3) applied over the step that ended here
    target_att_xyzw: np.ndarray   # (T, 4)

    _index: dict[str, int] | None = None

    def position_of(self, sid: str) -> np.ndarray | None:
        if self._index is None:
            self._index = {s: i for i, s in enumerate(self.ids)}
        i = self._index.get(sid)
        return None if i is None else self.pos_m[i]


def truth_frame(msg: pb.Truth) -> TruthFrame:
    sc = [b for b in msg.bodies if b.kind in ("", "spacecraft")]
    tg = [b for b in msg.bodies if b.kind not in ("", "spacecraft")]  # targets, debris, ...: world/targets/<id>

    def xyz(bodies: list[pb.BodyState]) -> np.ndarray:
        return np.array([(b.position_m.x, b.position_m.y, b.position_m.z) for b in bodies], float).reshape(-1, 3)

    def att(bodies: list[pb.BodyState]) -> tuple[np.ndarray, np.ndarray]:
        """(unit quaternions wxyz, where the truth has one): identity elsewhere."""
        q = np.array([(b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z) if b.HasField("attitude") else (1.0, 0, 0, 0)
                      for b in bodies], float).reshape(-1, 4)
        norm = np.linalg.norm(q, axis=1, keepdims=True)
        ok = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0)
        q[ok] /= norm[ok]
        q[~ok] = (1.0, 0.0, 0.0, 0.0)
        return q, ok & np.array([b.HasField("attitude") for b in bodies], bool)

    n, t = float(msg.mean_motion_radps), float(msg.header.t)
    q_sc, flown = att(sc)
    q_sc[flown] = lvlh_attitude_wxyz(q_sc[flown], n, t)   # body -> inertial (t = 0 LVLH) -> body -> LVLH
    return TruthFrame(int(msg.header.step), t, float(msg.u_rad), n,
                      tuple(b.id for b in sc), xyz(sc), np.array([b.alive for b in sc], bool),
                      np.array([b.delta_v_mps for b in sc], float), tuple(b.id for b in tg), xyz(tg),
                      wxyz_to_xyzw(q_sc),
                      np.array([(b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z) for b in sc], float).reshape(-1, 3),
                      wxyz_to_xyzw(att(tg)[0]))


class Paths:
    WORLD = "world"
    AXES = "world/axes"
    SWARM = "world/swarm"
    TRAILS = "world/trails"
    VISIBILITY = "world/visibility"
    LINKS = "world/links"
    ESTIMATES = "world/estimates"
    ESTIMATE_ERRORS = "world/estimates/error"
    WCC = "metrics/connectivity/weakly_connected_components"
    DV_TOTAL = "metrics/delta_v/total_mps"
    LINK_TX = "link/messages/tx"
    LINK_RX = "link/messages/rx"
    LINK_PAYLOAD_B = "link/bytes/payload"
    LINK_WIRE_B = "link/bytes/wire"
    LINK_DROPPED = "link/dropped"
    EVENTS = "events"
    FAULTY = "world/faulty"           # the spacecraft a [[fault]] strikes, while it lasts (issue 27)

    THRUST = "world/thrust"
    DV_BY_SC = "metrics/delta_v_by_spacecraft"

    @staticmethod
    def target(tid: str, part: str = "") -> str:
        """world/targets/<id>, and its `shape`."""
        return f"world/targets/{tid}/{part}".rstrip("/")

    @staticmethod
    def spacecraft(sid: str, part: str = "") -> str:
        """world/sc/<id>, and its `camera` (pinhole), `camera/image`, `sensor`, `landmarks`."""
        return f"world/sc/{sid}/{part}".rstrip("/")

    @staticmethod
    def camera(sid: str) -> str:
        return Paths.spacecraft(sid, "camera/image")

    @staticmethod
    def delta_v(sid: str) -> str:
        return f"{Paths.DV_BY_SC}/{sid}"


def blueprint(trail_steps: int, step_s: float, cameras: Iterable[str] = ()) -> rrb.Blueprint:
    """Default layout: 3D swarm with trails and the event log; time series on the right."""
    trail = rrb.VisibleTimeRanges([
        rrb.VisibleTimeRange(STEP, start=rrb.TimeRangeBoundary.cursor_relative(seq=-int(trail_steps)),
                             end=rrb.TimeRangeBoundary.cursor_relative()),
        rrb.VisibleTimeRange(SIM_TIME, start=rrb.TimeRangeBoundary.cursor_relative(seconds=-trail_steps * step_s),
                             end=rrb.TimeRangeBoundary.cursor_relative()),
    ])
    left = rrb.Vertical(
        rrb.Spatial3DView(origin=Paths.WORLD, name="swarm, LVLH m (x radial red, y along-track green, z cross-track blue)", overrides={Paths.TRAILS: trail}),
        rrb.TextLogView(origin=Paths.EVENTS, name="events"),
        row_shares=[4, 1],
    )
    plots: list[Any] = [
        rrb.TimeSeriesView(origin="metrics/connectivity", name="weakly connected components"),
        rrb.TimeSeriesView(origin="metrics/delta_v", name="total ΔV (m/s)"),
        rrb.TimeSeriesView(origin=Paths.DV_BY_SC, name="ΔV per spacecraft (m/s)"),
        rrb.TimeSeriesView(origin="link/messages", name="link messages"),
        rrb.TimeSeriesView(origin="link/bytes", name="link bytes"),
    ]
    cams = sorted(cameras)[:4]
    if cams:
        plots.append(rrb.Grid(*[rrb.Spatial2DView(origin=Paths.spacecraft(c, "camera"), name=f"camera {c}") for c in cams]))
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*plots), column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=STEP),
        collapse_panels=False,
    )


def _colour_array(colours: list[tuple[int, int, int]]) -> np.ndarray:
    return np.array(colours, np.uint8).reshape(-1, 3)


class _Estimates:
    """Believed neighbour positions of many agents and steps, resolved in one vectorised pass.

    Each estimate is the agent's true position plus its estimated relative position: a track's
    position_m, or a decision's relative ROE mapped to LVLH at the step's u (one call for all).
    """

    def __init__(self) -> None:
        self.own: list[np.ndarray] = []
        self.rel: list[Any] = []          # relative position, or None for a decision (ROE row below)
        self.true: list[np.ndarray | None] = []
        self.colours: list[tuple[int, int, int]] = []
        self.labels: list[str] = []
        self.roe: list[list[float]] = []
        self.roe_u: list[float] = []
        self.roe_n: list[float] = []
        self.roe_slot: list[int] = []
        self.n_err = 0

    @property
    def n(self) -> int:
        return len(self.own)

    def _append(self, own: np.ndarray, rel: Any, true: np.ndarray | None, behaviour: str, label: str) -> None:
        self.own.append(own)
        self.rel.append(rel)
        self.true.append(true)
        self.colours.append(mode_colour(behaviour))
        self.labels.append(label)
        self.n_err += true is not None

    def add(self, f: TruthFrame, sid: str, m: pb.Telemetry) -> None:
        if not len(m.tracks) and not len(m.decisions):
            return
        own = f.position_of(sid)
        if own is None:
            return
        behaviour = {d.neighbour: d.behaviour for d in m.decisions}
        if len(m.tracks):
            for tr in m.tracks:
                nb = tr.truth_id
                self._append(own, (tr.position_m.x, tr.position_m.y, tr.position_m.z), f.position_of(nb) if nb else None,
                             behaviour.get(nb, "none"), f"{sid}>{nb}" if nb else sid)
            return
        for d in m.decisions:
            if len(d.roe_rel_m) != 6:
                continue
            self.roe_slot.append(self.n)
            self.roe.append(list(d.roe_rel_m))
            self.roe_u.append(f.u_rad)
            self.roe_n.append(f.n_radps)
            self._append(own, None, f.position_of(d.neighbour), d.behaviour, f"{sid}>{d.neighbour}")

    def resolve(self) -> tuple[np.ndarray, np.ndarray]:
        """(estimated positions (n, 3), error segments estimate -> truth (n_err, 2, 3))."""
        rel = np.zeros((self.n, 3))
        direct = [i for i, r in enumerate(self.rel) if r is not None]
        if direct:
            rel[direct] = np.array([self.rel[i] for i in direct], float)
        if self.roe:
            rel[self.roe_slot] = roe_rel_to_position_m(np.array(self.roe), np.array(self.roe_u), self.roe_n[0])  # position needs no n
        pts = np.array(self.own, float).reshape(-1, 3) + rel
        err = [(pts[i], t) for i, t in enumerate(self.true) if t is not None]
        return pts, np.array(err, float).reshape(-1, 2, 3)


class SwarmLogger:
    """Queues raw samples of one run and logs them to a RecordingStream in column batches.

    Not thread-safe: call ingest/flush from one thread or under one lock (viz_node does).
    """

    HISTORY_STEPS = 600   # truth frames kept for late telemetry, link deliveries and images

    def __init__(self, rec: rr.RecordingStream, run: str, *, camera: CameraRule | None = None,
                 trail_steps: int = 570, step_s: float = 10.0, auto_flush_steps: int = 256,
                 config: dict[str, Any] | None = None) -> None:
        """config: the run's resolved configuration (cameras, sensor cones, shapes, thrust scale:
        dashboards/rerun_bodies.py SceneSpec); without it bodies get frames, axes and thrust only."""
        self.rec = rec
        self.spec = SceneSpec.from_config(config)
        self._lengths: dict[str, float] | None = None
        self._thrust_scale: float | None = None
        self.run = run
        self.keys = Keys(run)
        self.camera = camera or CameraRule()
        self.trail_steps = int(trail_steps)
        self.step_s = float(step_s)
        self.auto_flush_steps = auto_flush_steps
        self.rejections = Rejections("viz")
        self.counts: dict[str, int] = defaultdict(int)
        self._raw: dict[str, list[tuple[str | None, bytes]]] = defaultdict(list)
        self._truth_queued = 0
        self._history: dict[int, TruthFrame] = {}
        self._links: dict[int, list[tuple[str, str]]] = defaultdict(list)
        self._links_new: set[int] = set()
        self._tm: dict[int, dict[str, pb.Telemetry]] = defaultdict(dict)
        self._done_step = -1           # mode colours and estimates are logged up to this step
        self._modes: dict[str, str] = {}
        self._last_colours: np.ndarray | None = None
        self._colour_key: tuple[Any, ...] | None = None
        self._had_estimates = False
        self._static_ids: tuple[str, ...] | None = None
        self._static_targets: set[str] = set()
        self._cameras: set[str] = set()
        self._faults: dict[str, dict[str, Any]] = {}  # fault name -> kind, targets, start and end step (faults topic)
        self.flushes = 0
        self.last_step = -1
        self.blueprints_sent = 0
        self.send_blueprint()

    # --- input ------------------------------------------------------------------------------
    def ingest(self, key: str, payload: bytes) -> bool:
        """Queue one sample; True when enough truth is queued that the caller should flush."""
        try:
            kind, sid, sense_kind = self.keys.parse(key)
        except ValueError as exc:
            self.rejections.add(key, str(exc))
            return False
        if kind not in ("truth", "tm", "tm_image", "event", "faults", "link_stats", "isl_rx"):
            if kind != "sense" or self.spec.landmark_kind is None or sense_kind != self.spec.landmark_kind:
                return False
        self.counts[kind] += 1
        self._raw[kind].append((sid, payload))
        if kind == "truth":
            self._truth_queued += 1
            return self._truth_queued >= self.auto_flush_steps
        return False

    def send_blueprint(self) -> None:
        """The layout; the logger sends it once, when it is made (camera views from the configuration)."""
        self.rec.send_blueprint(blueprint(self.trail_steps, self.step_s, self.spec.image_ids))
        self.blueprints_sent += 1

    # --- output -----------------------------------------------------------------------------
    def flush(self, final: bool = False) -> None:
        """Decode everything queued and log it."""
        raw, self._raw = self._raw, defaultdict(list)
        self._truth_queued = 0
        self._log_fault_events(raw.get("faults", []))  # before the frames: they mark the struck spacecraft
        frames = self._decode_truths(raw.get("truth", []))
        for sid, payload in raw.get("isl_rx", []):
            self._queue_delivery(sid, payload)
        fresh = {f.step for f in frames}
        late_link_steps = sorted(s for s in self._links_new if s in self._history and s not in fresh)
        self._links_new = set()
        if frames:
            self._log_frames(frames)
        if late_link_steps:
            self._log_links(late_link_steps)
        self._queue_telemetry(raw.get("tm", []))
        self._log_completed_steps(final)
        self._log_events(raw.get("event", []))
        self._log_link_stats(raw.get("link_stats", []))
        self._log_images(raw.get("tm_image", []))
        self._log_landmarks(raw.get("sense", []))
        self._prune()
        self.flushes += 1

    def _decode(self, cls: type, key_kind: str, payload: bytes) -> Any | None:
        """Parse and check the run; no per-field finiteness walk (bus/codec.decode costs ~100 us a
        message: too much for the viewer, which only draws what it gets)."""
        try:
            msg = cls.FromString(payload)
        except (DecodeError, RuntimeWarning, ValueError) as exc:
            self.rejections.add(key_kind, f"{cls.DESCRIPTOR.name}: payload of {len(payload)} B does not decode ({exc})")
            return None
        if msg.header.run != self.run:
            self.rejections.add(key_kind, f"{cls.DESCRIPTOR.name}: header.run {msg.header.run!r} is not {self.run!r}")
            return None
        return msg

    def _decode_truths(self, items: list[tuple[str | None, bytes]]) -> list[TruthFrame]:
        frames = []
        for _sid, payload in items:
            msg = self._decode(pb.Truth, "truth", payload)
            if msg is None:
                continue
            f = truth_frame(msg)
            frames.append(f)
            self._history[f.step] = f
        frames.sort(key=lambda f: f.step)
        return frames

    def _queue_delivery(self, dst: str | None, payload: bytes) -> None:
        pkt = self._decode(pb.IslPacket, "isl_rx", payload)
        if pkt is None:
            return
        step = int(pkt.header.step)
        self._links[step].append((pkt.src, pkt.dst or (dst or "")))
        self._links_new.add(step)

    def _send(self, path: str, steps: Any, times_s: Any, columns: Any) -> None:
        self.rec.send_columns(path, indexes=[rr.TimeColumn(STEP, sequence=np.asarray(steps, np.int64)),
                                             rr.TimeColumn(SIM_TIME, duration=np.asarray(times_s, float))],
                              columns=columns)

    def _log_static(self, f: TruthFrame) -> None:
        if self._lengths is None:
            self._lengths = display_lengths(np.concatenate([f.pos_m, f.target_pos_m]))
        if self._static_ids is None:
            self.rec.log(Paths.WORLD, rr.ViewCoordinates.RIGHT_HAND_X_UP, static=True)
            self.rec.log(Paths.AXES, rr.Arrows3D(vectors=np.eye(3) * self._lengths["world_axes_m"], colors=[(230, 60, 60), (60, 200, 60), (70, 110, 255)],
                                                 labels=["x radial", "y along-track", "z cross-track"], show_labels=False,
                                                 radii=-1.0), static=True)
            self.rec.log(Paths.THRUST, rr.Arrows3D.from_fields(colors=[THRUST_COLOUR], radii=[-1.5]), static=True)
        if f.ids != self._static_ids:
            for sid in f.ids:
                if self._static_ids is None or sid not in self._static_ids:
                    self._log_body_static(sid)
            self.rec.log(Paths.SWARM, rr.Points3D.from_fields(labels=list(f.ids), radii=[SC_RADIUS_UI], show_labels=True),
                         static=True)
            self.rec.log(Paths.TRAILS, rr.Points3D.from_fields(colors=id_colours(len(f.ids)), radii=[TRAIL_RADIUS_UI]),
                         static=True)
            self._static_ids = f.ids
            self._last_colours = None
            self._colour_key = None
        for tid in f.target_ids:
            if tid not in self._static_targets:
                self.rec.log(Paths.target(tid), rr.Points3D(positions=[[0.0, 0.0, 0.0]], labels=[tid], radii=[TARGET_RADIUS_UI],
                                                            colors=[TARGET_COLOUR]), static=True)
                shape = shape_ellipsoids(self.spec.shapes.get(tid))
                if shape is not None:
                    self.rec.log(Paths.target(tid, "shape"), rr.Ellipsoids3D(centers=shape[0], half_sizes=shape[1], colors=[SHAPE_COLOUR],
                                                                          fill_mode="solid"), static=True)
                self._static_targets.add(tid)

    def _log_body_static(self, sid: str) -> None:
        """Body axes, camera (pinhole on its mount) and sensor cone of one spacecraft, in its frame."""
        L = self._lengths or display_lengths(np.zeros((1, 3)))
        self.rec.log(Paths.spacecraft(sid), rr.TransformAxes3D(L["axes_m"]), static=True)
        cam = self.spec.camera
        if cam is not None:
            self.rec.log(Paths.spacecraft(sid, "camera"), rr.Transform3D(mat3x3=R_LVLH_FROM_CAM),
                         rr.Pinhole(focal_length=cam.focal_px, width=cam.width_px, height=cam.height_px,
                                    image_plane_distance=L["frustum_m"], color=CAMERA_COLOUR), static=True)
        if self.spec.cone is not None:
            self.rec.log(Paths.spacecraft(sid, "sensor"), rr.LineStrips3D(cone_strips(*self.spec.cone), colors=[CONE_COLOUR],
                                                            radii=[LINE_RADIUS_UI]), static=True)

    def _log_frames(self, frames: list[TruthFrame]) -> None:
        # runs of consecutive frames with the same bodies are logged as one batch per entity
        start = 0
        for i in range(1, len(frames) + 1):
            if i == len(frames) or frames[i].ids != frames[start].ids or frames[i].target_ids != frames[start].target_ids:
                self._log_frame_batch(frames[start:i])
                start = i

    def _log_frame_batch(self, frames: list[TruthFrame]) -> None:
        f0 = frames[0]
        self._log_static(f0)
        steps = np.array([f.step for f in frames], np.int64)
        t_s = np.array([f.t_s for f in frames])
        pos = np.stack([f.pos_m for f in frames])          # (M, N, 3)
        alive = np.stack([f.alive for f in frames])         # (M, N)
        m, n = alive.shape
        self.last_step = max(self.last_step, int(steps[-1]))
        per_step = np.full(m, n)
        self._send(Paths.SWARM, steps, t_s, rr.Points3D.columns(positions=pos.reshape(-1, 3)).partition(per_step))
        self._send(Paths.TRAILS, steps, t_s, rr.Points3D.columns(positions=pos.reshape(-1, 3)).partition(per_step))
        vis = visibility_series(pos, self.camera, alive)
        s_idx, j_idx, k_idx = np.nonzero(vis)
        strips = np.stack([pos[s_idx, j_idx], pos[s_idx, k_idx]], axis=1)
        self._send(Paths.VISIBILITY, steps, t_s,
                   rr.LineStrips3D.columns(strips=strips, radii=np.full(len(strips), LINE_RADIUS_UI, np.float32),
                                           colors=np.tile(np.array(VISIBILITY_COLOUR, np.uint8), (len(strips), 1)))
                   .partition(np.bincount(s_idx, minlength=m)))
        self._send(Paths.WCC, steps, t_s, rr.Scalars.columns(scalars=weak_components(vis, alive)[0].astype(float)))
        self._send(Paths.DV_TOTAL, steps, t_s, rr.Scalars.columns(scalars=np.stack([f.delta_v_mps for f in frames]).sum(axis=1)))
        for ti, tid in enumerate(f0.target_ids):
            self._send(Paths.target(tid), steps, t_s,
                       rr.Transform3D.columns(translation=np.stack([f.target_pos_m[ti] for f in frames]),
                                              quaternion=np.stack([f.target_att_xyzw[ti] for f in frames])))
        att = np.stack([f.att_xyzw for f in frames])          # (M, N, 4)
        dv = np.stack([f.delta_v_mps for f in frames])        # (M, N)
        for i, sid in enumerate(f0.ids):
            self._send(Paths.spacecraft(sid), steps, t_s, rr.Transform3D.columns(translation=pos[:, i], quaternion=att[:, i]))
            self._send(Paths.delta_v(sid), steps, t_s, rr.Scalars.columns(scalars=dv[:, i]))
        acc = np.stack([f.accel_mps2 for f in frames])        # (M, N, 3)
        self._send(Paths.THRUST, steps, t_s,
                   rr.Arrows3D.columns(origins=pos.reshape(-1, 3), vectors=(acc * self._thrust_m_per_mps2(acc)).reshape(-1, 3))
                   .partition(per_step))
        self._log_links([int(s) for s in steps])
        if self._faults:
            self._log_faulty(f0.ids, steps, t_s, pos)

    def _log_faulty(self, ids: list[str], steps: np.ndarray, t_s: np.ndarray, pos: np.ndarray) -> None:
        """world/faulty: a ring on each spacecraft a fault strikes at that step (its targets, from the
        `faults` topic's fault_start up to its fault_end), labelled with the fault's kind; an empty
        list at steps without one, so the ring goes when the fault ends."""
        struck = np.zeros(pos.shape[:2], dtype=bool)
        labels: list[list[str]] = [[""] * len(ids) for _ in steps]
        col = {sid: i for i, sid in enumerate(ids)}
        for f in self._faults.values():
            live = (steps >= f["start"]) & ((steps < f["end"]) if f["end"] is not None else True)
            for sid in f["targets"]:
                if sid in col:
                    struck[live, col[sid]] = True
                    for m in np.flatnonzero(live):
                        labels[m][col[sid]] = ", ".join(x for x in (labels[m][col[sid]], f["kind"]) if x)
        m_idx, i_idx = np.nonzero(struck)
        self._send(Paths.FAULTY, steps, t_s,
                   rr.Points3D.columns(positions=pos[m_idx, i_idx], labels=[labels[m][i] for m, i in zip(m_idx, i_idx)],
                                       radii=np.full(len(m_idx), FAULT_RADIUS_UI, np.float32),
                                       colors=np.tile(np.array(FAULT_COLOUR, np.uint8), (len(m_idx), 1)))
                   .partition(np.bincount(m_idx, minlength=len(steps))))

    def _log_fault_events(self, items: list[tuple[str | None, bytes]]) -> None:
        """The `faults` topic: each fault_start / fault_end into the event log (WARN) and into the
        windows world/faulty is drawn from (detail: the fault's table as JSON, plant/node.py)."""
        steps, times, texts = [], [], []
        for _sid, payload in items:
            ev = self._decode(pb.Event, "faults", payload)
            if ev is None:
                continue
            step = int(ev.header.step)
            steps.append(step)
            times.append(ev.header.t)
            texts.append(f"{ev.kind} {ev.subject}: {ev.detail}")
            try:
                table = json.loads(ev.detail)
            except ValueError:
                table = {}
            f = self._faults.setdefault(ev.subject, {"kind": str(table.get("kind", "fault")), "start": step,
                                                     "end": None, "targets": list(table.get("targets") or [])})
            if ev.kind == "fault_end":
                f["end"] = step
        if steps:
            self._send(Paths.EVENTS, steps, times, rr.TextLog.columns(text=texts, level=["WARN"] * len(texts)))

    def _thrust_m_per_mps2(self, acc: np.ndarray) -> float:
        """Arrow length per m/s^2: the display length at the acceleration limit of the configuration,
        else at the largest acceleration of the first batch that has one (then kept)."""
        if self._thrust_scale is None:
            ref = self.spec.accel_ref_mps2
            if ref is None:
                mags = np.linalg.norm(acc, axis=-1)
                ref = float(mags[np.isfinite(mags)].max()) if np.isfinite(mags).any() else 0.0
                if ref <= 0.0:
                    return 0.0
            self._thrust_scale = (self._lengths or display_lengths(np.zeros((1, 3))))["thrust_m"] / ref
        return self._thrust_scale

    def _log_links(self, steps: list[int]) -> None:
        """ISL deliveries of each step as segments between the true positions (empty when none)."""
        segs, counts, times = [], [], []
        for s in steps:
            f = self._history[s]
            c = 0
            for src, dst in self._links.get(s, ()):
                a, b = f.position_of(src), f.position_of(dst)
                if a is not None and b is not None:
                    segs.append((a, b))
                    c += 1
            counts.append(c)
            times.append(f.t_s)
        strips = np.array(segs, float).reshape(-1, 2, 3)
        self._send(Paths.LINKS, steps, times,
                   rr.LineStrips3D.columns(strips=strips, colors=np.tile(np.array(LINK_COLOUR, np.uint8), (len(strips), 1)),
                                           radii=np.full(len(strips), 2 * LINE_RADIUS_UI, np.float32)).partition(counts))

    def _queue_telemetry(self, items: list[tuple[str | None, bytes]]) -> None:
        for sid, payload in items:
            msg = self._decode(pb.Telemetry, "tm", payload)
            if msg is None or sid is None:
                continue
            step = int(msg.header.step)
            if step <= self._done_step:
                self._modes[sid] = msg.mode   # late: its step is drawn already; keep the mode current
                continue
            self._tm[step][sid] = msg

    def _log_completed_steps(self, final: bool) -> None:
        """Mode colours and estimates of every step whose telemetry is complete (see module doc)."""
        last = max(self._history) if self._history else -1
        # step k is complete once truth k+2 is in: the plant publishes truth k+2 only after every
        # agent's command of step k+1, which each agent sends after its telemetry of step k, so
        # through the router every receiver (live bridge, recorder) has that telemetry by then
        todo = sorted(s for s in self._history if self._done_step < s and (s < last - 1 or final))
        c_steps, c_times, c_rows = [], [], []
        est = _Estimates()
        e_steps, e_times, e_n, e_nerr = [], [], [], []
        for s in todo:
            f = self._history[s]
            tms = self._tm.pop(s, {})
            for sid, msg in tms.items():
                self._modes[sid] = msg.mode
            key = (f.ids, f.alive.tobytes(), tuple(self._modes.get(sid, "idle") for sid in f.ids))
            if key != self._colour_key:
                colours = _colour_array([DEAD_COLOUR if not a else mode_colour(mode) for a, mode in zip(f.alive, key[2])])
                if self._last_colours is None or not np.array_equal(colours, self._last_colours):
                    c_steps.append(s)
                    c_times.append(f.t_s)
                    c_rows.append(colours)
                    self._last_colours = colours
                self._colour_key = key
            n0, ne0 = est.n, est.n_err
            for sid in sorted(tms):
                est.add(f, sid, tms[sid])
            if est.n > n0 or self._had_estimates:
                e_steps.append(s)
                e_times.append(f.t_s)
                e_n.append(est.n - n0)
                e_nerr.append(est.n_err - ne0)
                self._had_estimates = est.n > n0
            self._done_step = s
        if todo and self._last_colours is not None and (not c_steps or c_steps[-1] != todo[-1]):
            # repeat the colours at the newest step of each flush: a viewer that joins late gets the
            # newest data first (GrpcServerSink newest_first) and must not wait for the first row
            c_steps.append(todo[-1])
            c_times.append(self._history[todo[-1]].t_s)
            c_rows.append(self._last_colours)
        for s in [s for s in self._tm if s <= self._done_step]:
            for sid, msg in self._tm.pop(s).items():
                self._modes[sid] = msg.mode
        if c_steps:
            self._send(Paths.SWARM, c_steps, c_times,
                       rr.Points3D.columns(colors=np.concatenate(c_rows)).partition([len(c) for c in c_rows]))
        if e_steps:
            pts, strips = est.resolve()
            self._send(Paths.ESTIMATES, e_steps, e_times,
                       rr.Points3D.columns(positions=pts, colors=_colour_array(est.colours), labels=est.labels,
                                           radii=np.full(len(pts), ESTIMATE_RADIUS_UI, np.float32)).partition(e_n))
            self._send(Paths.ESTIMATE_ERRORS, e_steps, e_times,
                       rr.LineStrips3D.columns(strips=strips, colors=np.tile(np.array(ERROR_COLOUR, np.uint8), (len(strips), 1)),
                                               radii=np.full(len(strips), LINE_RADIUS_UI, np.float32)).partition(e_nerr))

    def _log_events(self, items: list[tuple[str | None, bytes]]) -> None:
        steps, times, texts, levels = [], [], [], []
        for _sid, payload in items:
            ev = self._decode(pb.Event, "event", payload)
            if ev is None:
                continue
            steps.append(int(ev.header.step))
            times.append(ev.header.t)
            texts.append(f"{ev.kind} {ev.subject}: {ev.detail}" if ev.detail else f"{ev.kind} {ev.subject}")
            levels.append(EVENT_LEVELS.get(ev.kind, "INFO"))
        if steps:
            self._send(Paths.EVENTS, steps, times, rr.TextLog.columns(text=texts, level=levels))

    def _log_link_stats(self, items: list[tuple[str | None, bytes]]) -> None:
        rows = []
        for _sid, payload in items:
            st = self._decode(pb.LinkStats, "link_stats", payload)
            if st is None:
                continue
            links = st.links
            rows.append((int(st.header.step), st.header.t, float(st.tx_messages), float(st.rx_messages),
                         float(sum(c.payload_bytes for c in links)), float(sum(c.wire_bytes for c in links)),
                         float(sum(c.dropped_range + c.dropped_occulted + c.dropped_lost + c.dropped_queue for c in links))))
        if not rows:
            return
        rows.sort(key=lambda r: r[0])
        cols = np.array([r[2:] for r in rows])
        steps, times = [r[0] for r in rows], [r[1] for r in rows]
        for i, path in enumerate((Paths.LINK_TX, Paths.LINK_RX, Paths.LINK_PAYLOAD_B, Paths.LINK_WIRE_B, Paths.LINK_DROPPED)):
            self._send(path, steps, times, rr.Scalars.columns(scalars=cols[:, i]))

    def _log_images(self, items: list[tuple[str | None, bytes]]) -> None:
        if not items:
            return
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        for sid, payload in items:
            try:
                img = CompressedImage.FromString(payload)
            except (DecodeError, RuntimeWarning, ValueError) as exc:
                self.rejections.add("tm_image", f"CompressedImage does not decode: {exc}")
                continue
            if sid is None or not img.data:
                continue
            t_s = img.timestamp.seconds + img.timestamp.nanos * 1e-9
            fmt = (img.format or "jpeg").lower()
            self._send(Paths.camera(sid), [self._step_at(t_s)], [t_s],
                       rr.EncodedImage.columns(blob=[img.data], media_type=[f"image/{fmt}"]))
            self._cameras.add(sid)

    def _log_landmarks(self, items: list[tuple[str | None, bytes]]) -> None:
        """Landmark returns of each step in the body frame of the agent (empty when none), outliers red."""
        if not items or self.spec.landmark_kind is None:
            return

        pts_name, ids_name = LANDMARK_KINDS[self.spec.landmark_kind]
        per: dict[str, list[tuple[int, float, np.ndarray, np.ndarray]]] = defaultdict(list)
        for sid, payload in items:
            msg = self._decode(pb.Measurements, "sense", payload)
            if msg is None or sid is None:
                continue
            pts, ids = np.zeros((0, 3)), np.zeros(0)
            for it in msg.items:
                if it.name == pts_name:
                    pts = np.asarray(it.values, float).reshape(-1, 3)
                elif it.name == ids_name:
                    ids = np.asarray(it.values, float).reshape(-1)
            if len(ids) != len(pts):
                ids = np.zeros(len(pts))
            per[sid].append((int(msg.header.step), float(msg.header.t), pts, ids))
        for sid, rows in per.items():
            rows.sort(key=lambda r: r[0])
            pts = np.concatenate([r[2] for r in rows]).reshape(-1, 3)
            out = np.concatenate([r[3] for r in rows]) < 0
            colours = np.where(out[:, None], np.array(OUTLIER_COLOUR, np.uint8), np.array(LANDMARK_COLOUR, np.uint8)).astype(np.uint8)
            self._send(Paths.spacecraft(sid, "landmarks"), [r[0] for r in rows], [r[1] for r in rows],
                       rr.Points3D.columns(positions=pts, colors=colours.reshape(-1, 3),
                                           radii=np.full(len(pts), -2.0, np.float32)).partition([len(r[2]) for r in rows]))

    def _step_at(self, t_s: float) -> int:
        """Step of the truth frame nearest in time (images carry a timestamp, not a step)."""
        if self._history:
            return min(self._history.values(), key=lambda f: abs(f.t_s - t_s)).step
        return int(round(t_s / self.step_s)) if self.step_s > 0 else 0

    def _prune(self) -> None:
        if len(self._history) <= self.HISTORY_STEPS:
            return
        keep = sorted(self._history)[-self.HISTORY_STEPS:]
        cut = keep[0]
        self._history = {s: self._history[s] for s in keep}
        for s in [s for s in self._links if s < cut]:
            del self._links[s]

    def stats(self) -> dict[str, Any]:
        return {"samples": dict(self.counts), "rejected": self.rejections.total, "flushes": self.flushes,
                "last_step": self.last_step, "cameras": sorted(self._cameras)}


def trail_steps_for(step_s: float, n_radps: float, viz_cfg: dict[str, Any] | None = None) -> int:
    """Trail length in steps: `[viz] trail_s` of the scenario, else one orbital period 2*pi/n."""
    trail_s = float((viz_cfg or {}).get("trail_s", 2.0 * math.pi / n_radps))
    return max(1, int(round(trail_s / step_s)))
