"""Read the plant's truth out of a recording into numpy arrays (DESIGN.md "MCAP (contract)").

Only the public contract is used: the `mcap` reader with the `mcap-protobuf-support` decoder,
which decodes from the FileDescriptorSet embedded in the file, so this reads any swarmhil
recording without the project's generated classes. The truth topic is `truth` (the run id in the
metadata `swarmhil.run`); recordings made before the MCAP contract have `swarm/<run>/truth`, and
both are read. Each `swarmhil.v1.Truth` message is one step k, with the state at t_k.

`accel_cmd_mps2` of step k is, in the current contract (bus/swarmhil.proto), the acceleration
applied over the step that *ended* at t_k; recordings made before that change carry the one
applied over the step that *starts* at t_k. Which one a file holds is decided from the data: the
cumulative dV increments dv(t_k+1) - dv(t_k) equal |a| dt of the command applied over that step.
`TruthArrays.accel_mps2[k]` is always the command applied over [t_k, t_k+1) (zero at the end).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmhil.bus.keys import split_topic
from swarmhil.bus.mcap_tools import find_topic, run_of_recording
from swarmhil.plant.dynamics.roe_linear import lvlh_to_roe

TRUTH_SCHEMA = "swarmhil.v1.Truth"


@dataclass(frozen=True)
class TruthArrays:
    """The truth of one run, one row per recorded step (sorted by step, duplicates dropped)."""

    run: str
    ids: list[str]
    step: np.ndarray  # (T,) lockstep step index
    t_s: np.ndarray  # (T,) simulation time
    u_rad: np.ndarray  # (T,) reference mean argument of latitude
    semi_major_axis_m: float
    mean_motion_radps: float
    position_m: np.ndarray  # (T, N, 3) LVLH (x radial, y along-track, z cross-track)
    velocity_mps: np.ndarray  # (T, N, 3)
    delta_v_mps: np.ndarray  # (T, N) cumulative at t_k
    alive: np.ndarray  # (T, N) bool
    accel_mps2: np.ndarray  # (T, N, 3) command applied over [t_k, t_k+1) (after the actuator limit)
    roe_m: np.ndarray  # (T, N, 6) a*(da, dl, dex, dey, dix, diy) w.r.t. the reference orbit
    accel_recorded_as: str = "ended"  # what the file's accel_cmd_mps2 meant: "ended" or "starts" at t_k

    @property
    def n_steps(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def n_bodies(self) -> int:
        return len(self.ids)


def run_id_of(run_dir: Path) -> str | None:
    """The run id from run_dir/summary.json, if there is one."""
    p = Path(run_dir) / "summary.json"
    if p.is_file():
        try:
            return str(json.loads(p.read_text())["run"])
        except (KeyError, ValueError):
            return None
    return None


def _truth_topic(reader, run: str | None) -> tuple[str, str]:
    """(truth topic, run id): `truth` of a current recording, `swarm/<run>/truth` of an old one."""
    summary = reader.get_summary()
    topics = sorted({ch.topic for ch in summary.channels.values()}) if summary is not None else []
    found = find_topic(topics, "truth", run)
    if len(found) != 1:
        raise ValueError(f"expected one truth topic, found {found or 'none'} (run {run!r})")
    topic = found[0]
    rec_run = split_topic(topic)[0] or run_of_recording(reader) or run or ""
    return topic, rec_run


def read_truth(mcap_path: str | Path, run: str | None = None) -> TruthArrays:
    """Every Truth message of the recording as arrays (T steps, N spacecraft)."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    mcap_path = Path(mcap_path)
    if run is None:
        run = run_id_of(mcap_path.parent)
    rows: dict[int, object] = {}
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        topic, run = _truth_topic(reader, run)
        for schema, _ch, _msg, truth in reader.iter_decoded_messages(topics=[topic]):
            if schema is None or schema.name != TRUTH_SCHEMA:
                continue  # e.g. an UndecodableSample kept by the recorder on the same topic
            rows.setdefault(int(truth.header.step), truth)
    if not rows:
        raise ValueError(f"{mcap_path}: no {TRUTH_SCHEMA} messages on {topic}")
    return _to_arrays(run, [rows[k] for k in sorted(rows)])


def _to_arrays(run: str, msgs: list) -> TruthArrays:
    ids = [b.id for b in msgs[0].bodies if b.kind in ("", "spacecraft")]
    col = {sid: i for i, sid in enumerate(ids)}
    T, N = len(msgs), len(ids)
    pos = np.full((T, N, 3), np.nan)
    vel = np.full((T, N, 3), np.nan)
    acc = np.zeros((T, N, 3))
    dv = np.full((T, N), np.nan)
    alive = np.zeros((T, N), dtype=bool)
    roe = np.full((T, N, 6), np.nan)
    step = np.empty(T, dtype=np.int64)
    t = np.empty(T)
    u = np.empty(T)
    for r, m in enumerate(msgs):
        step[r], t[r], u[r] = m.header.step, m.header.t, m.u_rad
        for b in m.bodies:
            i = col.get(b.id)
            if i is None:
                continue
            pos[r, i] = (b.position_m.x, b.position_m.y, b.position_m.z)
            vel[r, i] = (b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z)
            acc[r, i] = (b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z)
            dv[r, i] = b.delta_v_mps
            alive[r, i] = b.alive
            if len(b.roe_m) == 6:
                roe[r, i] = list(b.roe_m)
    a_m, n_radps = float(msgs[0].semi_major_axis_m), float(msgs[0].mean_motion_radps)
    missing = np.isnan(roe).any(axis=2)
    if missing.any():  # older recordings: the linear map of the LVLH state (NOTES-002 matrix M)

        for r in np.flatnonzero(missing.any(axis=1)):
            roe[r, missing[r]] = lvlh_to_roe(pos[r, missing[r]], vel[r, missing[r]], u[r], n_radps)
    acc, recorded_as = align_accel(acc, dv, t)
    return TruthArrays(run=run, ids=ids, step=step, t_s=t, u_rad=u, semi_major_axis_m=a_m,
                       mean_motion_radps=n_radps, position_m=pos, velocity_mps=vel, delta_v_mps=dv,
                       alive=alive, accel_mps2=acc, roe_m=roe, accel_recorded_as=recorded_as)


def align_accel(acc: np.ndarray, dv: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, str]:
    """Commands as applied over [t_k, t_k+1), from either recording convention (module docstring).

    The convention is the one whose |a| dt matches the recorded dV increments best; with no
    thrust at all both match and the current one ("ended") is assumed.
    """
    if acc.shape[0] < 2:
        return acc, "ended"
    inc = np.diff(dv, axis=0)
    dt = np.diff(t_s)[:, None]
    norm = np.linalg.norm(acc, axis=-1)
    err_ended = np.nansum(np.abs(norm[1:] * dt - inc))
    err_starts = np.nansum(np.abs(norm[:-1] * dt - inc))
    if err_starts < err_ended:
        return acc, "starts"
    shifted = np.zeros_like(acc)
    shifted[:-1] = acc[1:]
    return shifted, "ended"
