"""Reading a run's navigation from its recording: each agent's track estimates and behaviour decisions
(telemetry `sc/<id>/tm`) as flat rows (the package docstring says what they hold)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

TELEMETRY_SCHEMA = "swarmhil.v1.Telemetry"


@dataclass
class TrackRows:
    """Every track of every agent at every step, one row each (R rows)."""

    step: np.ndarray  # (R,) int
    observer: np.ndarray  # (R,) index into the truth ids
    track: np.ndarray  # (R,) int code of (observer, track id), unique over the run
    track_names: list[str]  # code -> "<observer>/<track id>"
    position_m: np.ndarray  # (R, 3) estimated r_k - r_j, LVLH
    velocity_mps: np.ndarray  # (R, 3)
    roe_m: np.ndarray  # (R, 6) estimated roe_k - roe_j
    covariance_m2: np.ndarray  # (R, 6, 6), NaN where the estimator has none
    age_steps: np.ndarray  # (R,)
    used: np.ndarray  # (R,) bool: the controller made a decision on this track at this step
    # (M,) every Telemetry message's step and observer, with or without tracks (what was reported at all)
    tm_step: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    tm_observer: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def n(self) -> int:
        return int(self.step.shape[0])


@dataclass
class DecisionRows:
    """Every behaviour decision (one per neighbour the controller used at a step)."""

    step: np.ndarray  # (D,)
    observer: np.ndarray  # (D,)
    neighbour: list[str]  # track id or, with `rel` sensing, the spacecraft id
    roe_jk_m: np.ndarray  # (D, 6) ROE of the observer relative to the neighbour, as the controller used it
    behaviour: list[str] = field(default_factory=list)  # (D,) "collision_avoidance", "alignment", "attraction", "none"
    accel_mps2: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (D, 3) this neighbour's contribution to the command


def _tm_topics(reader, run: str, ids: list[str]) -> dict[str, int]:
    summary = reader.get_summary()
    topics = {ch.topic for ch in summary.channels.values()} if summary is not None else set()
    want = {f"sc/{sid}/tm": j for j, sid in enumerate(ids)}
    want.update({f"swarm/{run}/sc/{sid}/tm": j for j, sid in enumerate(ids)})  # old recordings
    return {t: j for t, j in want.items() if t in topics}


def read_tracks(mcap_path: str | Path, run: str, ids: list[str]) -> tuple[TrackRows, DecisionRows]:
    """Tracks and decisions from every agent's Telemetry (decoded from the file's own schema)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    step, obs, code, pos, vel, roe, cov, age, used = [], [], [], [], [], [], [], [], []
    d_step, d_obs, d_nb, d_roe, d_beh, d_acc = [], [], [], [], [], []
    names: dict[tuple[int, str], int] = {}
    tm_step, tm_obs = [], []
    nan_cov = np.full(36, np.nan)
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topics = _tm_topics(reader, run, ids)
        if not topics:
            return _empty_tracks(), DecisionRows(np.zeros(0, int), np.zeros(0, int), [], np.zeros((0, 6)))
        for schema, ch, _msg, tm in reader.iter_decoded_messages(topics=list(topics)):
            if schema is None or schema.name != TELEMETRY_SCHEMA:
                continue
            j, k = topics[ch.topic], int(tm.header.step)
            tm_step.append(k)
            tm_obs.append(j)
            decided = set()
            for d in tm.decisions:
                decided.add(d.neighbour)
                if len(d.roe_rel_m) == 6:
                    d_step.append(k)
                    d_obs.append(j)
                    d_nb.append(d.neighbour)
                    d_roe.append(list(d.roe_rel_m))
                    d_beh.append(d.behaviour)
                    d_acc.append((d.accel_mps2.x, d.accel_mps2.y, d.accel_mps2.z))
            for tr in tm.tracks:
                if len(tr.roe_m) != 6:
                    continue
                c = names.setdefault((j, tr.track), len(names))
                step.append(k)
                obs.append(j)
                code.append(c)
                pos.append((tr.position_m.x, tr.position_m.y, tr.position_m.z))
                vel.append((tr.velocity_mps.x, tr.velocity_mps.y, tr.velocity_mps.z))
                roe.append(list(tr.roe_m))
                cov.append(list(tr.covariance_m2) if len(tr.covariance_m2) == 36 else nan_cov)
                age.append(tr.age_steps)
                used.append(tr.track in decided)
    track_names = [""] * len(names)
    for (j, tid), c in names.items():
        track_names[c] = f"{ids[j]}/{tid}"
    rows = TrackRows(
        step=np.asarray(step, dtype=np.int64), observer=np.asarray(obs, dtype=np.int64),
        track=np.asarray(code, dtype=np.int64), track_names=track_names,
        position_m=np.asarray(pos, float).reshape(-1, 3), velocity_mps=np.asarray(vel, float).reshape(-1, 3),
        roe_m=np.asarray(roe, float).reshape(-1, 6), covariance_m2=np.asarray(cov, float).reshape(-1, 6, 6),
        age_steps=np.asarray(age, dtype=np.int64), used=np.asarray(used, dtype=bool),
        tm_step=np.asarray(tm_step, dtype=np.int64), tm_observer=np.asarray(tm_obs, dtype=np.int64))
    dec = DecisionRows(np.asarray(d_step, dtype=np.int64), np.asarray(d_obs, dtype=np.int64), d_nb,
                       np.asarray(d_roe, float).reshape(-1, 6), d_beh, np.asarray(d_acc, float).reshape(-1, 3))
    return rows, dec


def _empty_tracks() -> TrackRows:
    z = np.zeros(0, dtype=np.int64)
    return TrackRows(z, z, z, [], np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 6)), np.zeros((0, 6, 6)), z,
                     np.zeros(0, dtype=bool))

