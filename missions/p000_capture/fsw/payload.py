"""What an agent broadcasts, as bytes (paper 000 §3.2.1 "state", §3.2.2 estimates, eq. 30).

`state` packet (little-endian, 84 bytes): version u8, mode u8, flags u8 (bit 0: carries a target
estimate), pad u8, then float32: t_s, position_m[3], velocity_mps[3] (own, CW frame), est_t_s,
centre_m[3], target_velocity_mps[3], shape matrix upper triangle M00 M01 M02 M11 M12 M22 (m⁻²).
`landmarks` packet: version u8, count u8, pad u16, float32 t_s, then count × int16[3] LVLH
landmark positions in millimetres (±32.767 m): returns pooled between neighbours (NOTES-000 trap 6).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STATE_TYPE = "p000-state"
LANDMARKS_TYPE = "p000-landmarks"
VERSION = 1
MODES = ("search", "chase", "dock")

_STATE = np.dtype([("version", "u1"), ("mode", "u1"), ("flags", "u1"), ("pad", "u1"),
                   ("t", "<f4"), ("r", "<f4", 3), ("v", "<f4", 3), ("est_t", "<f4"),
                   ("c", "<f4", 3), ("vt", "<f4", 3), ("m", "<f4", 6)])
_LM_HEAD = np.dtype([("version", "u1"), ("count", "u1"), ("pad", "<u2"), ("t", "<f4")])
_TRIU = np.triu_indices(3)


@dataclass
class StateMsg:
    t_s: float
    mode: str
    position_m: np.ndarray
    velocity_mps: np.ndarray
    est_t_s: float = float("nan")
    centre_m: np.ndarray | None = None           # None: no target estimate carried
    target_velocity_mps: np.ndarray | None = None
    shape: np.ndarray | None = None               # (3, 3) M


def encode_state(msg: StateMsg) -> bytes:
    rec = np.zeros((), dtype=_STATE)
    rec["version"], rec["mode"] = VERSION, MODES.index(msg.mode)
    rec["t"], rec["r"], rec["v"] = msg.t_s, msg.position_m, msg.velocity_mps
    if msg.centre_m is not None:
        rec["flags"] = 1
        rec["est_t"], rec["c"], rec["vt"] = msg.est_t_s, msg.centre_m, msg.target_velocity_mps
        rec["m"] = np.asarray(msg.shape)[_TRIU]
    return rec.tobytes()


def decode_state(data: bytes) -> StateMsg:
    if len(data) != _STATE.itemsize:
        raise ValueError(f"state packet is {len(data)} bytes, expected {_STATE.itemsize}")
    rec = np.frombuffer(data, dtype=_STATE)[0]
    if rec["version"] != VERSION:
        raise ValueError(f"state packet version {rec['version']}, expected {VERSION}")
    if rec["mode"] >= len(MODES):
        raise ValueError(f"state packet mode {rec['mode']} unknown")
    msg = StateMsg(float(rec["t"]), MODES[rec["mode"]], rec["r"].astype(float), rec["v"].astype(float))
    if rec["flags"] & 1:
        m = np.zeros((3, 3))
        m[_TRIU] = rec["m"]
        m = m + np.triu(m, 1).T
        msg.est_t_s, msg.centre_m = float(rec["est_t"]), rec["c"].astype(float)
        msg.target_velocity_mps, msg.shape = rec["vt"].astype(float), m
    return msg


def encode_landmarks(t_s: float, points_m: np.ndarray) -> bytes:
    pts = np.asarray(points_m, dtype=float).reshape(-1, 3)
    mm = np.round(pts * 1000.0)
    keep = np.all(np.abs(mm) <= 32767, axis=1)
    mm = mm[keep][:255].astype("<i2")
    head = np.zeros((), dtype=_LM_HEAD)
    head["version"], head["count"], head["t"] = VERSION, len(mm), t_s
    return head.tobytes() + mm.tobytes()


def decode_landmarks(data: bytes) -> tuple[float, np.ndarray]:
    head = np.frombuffer(data[:_LM_HEAD.itemsize], dtype=_LM_HEAD)[0]
    n = int(head["count"])
    if head["version"] != VERSION or len(data) != _LM_HEAD.itemsize + 6 * n:
        raise ValueError(f"landmarks packet of {len(data)} bytes does not hold {n} points (v{head['version']})")
    pts = np.frombuffer(data[_LM_HEAD.itemsize:], dtype="<i2").reshape(n, 3).astype(float) / 1000.0
    return float(head["t"]), pts
