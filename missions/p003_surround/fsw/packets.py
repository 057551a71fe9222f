"""Inter-satellite-link payloads of paper 003, compact little-endian binary.

- `p003.tt` (leader -> all, 41 B): version u8, step u32, the leader's applied acceleration
  a_L (3 x f32, m/s^2, leader LVLH: what the servicers' synchronous term u_Li follows, eq. 6),
  q_TL (3 x f32, m) and q'_TL (3 x f32, m/s), the measured target state the servicers place the
  ACSB spheres with (q_Cg = q_TL + d_Cg, §5).
- `p003.ct` (servicer -> all, 50 B): version u8, servicer index u8, its CT error x~_i and its block
  ξ_i of the immersion variable (6 + 6 x f32), which the others' ξ update (eq. 20) and threats need.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

VERSION = 1
TT_TYPE = "p003.tt"
CT_TYPE = "p003.ct"
_TT = struct.Struct("<BI9f")
_CT = struct.Struct("<BB12f")


@dataclass(frozen=True)
class TTPacket:
    step: int
    leader_accel_mps2: np.ndarray
    q_tl_m: np.ndarray
    v_tl_mps: np.ndarray


@dataclass(frozen=True)
class CTPacket:
    index: int
    x_err: np.ndarray
    xi: np.ndarray


def encode_tt(p: TTPacket) -> bytes:
    # tolist(): the same doubles as Python floats, which struct packs as it packs numpy's (issue 29)
    return _TT.pack(VERSION, p.step, *np.asarray(p.leader_accel_mps2, float).tolist(), *np.asarray(p.q_tl_m, float).tolist(),
                    *np.asarray(p.v_tl_mps, float).tolist())


def decode_tt(payload: bytes) -> TTPacket:
    if len(payload) != _TT.size:
        raise ValueError(f"{TT_TYPE} payload must be {_TT.size} bytes, got {len(payload)}")
    version, step, *vals = _TT.unpack(payload)
    if version != VERSION:
        raise ValueError(f"{TT_TYPE} version {version}, expected {VERSION}")
    v = np.array(vals, dtype=float)
    return TTPacket(step, v[0:3], v[3:6], v[6:9])


def encode_ct(p: CTPacket) -> bytes:
    return encode_ct_values(p.index, [*np.asarray(p.x_err, float).tolist(), *np.asarray(p.xi, float).tolist()])


def encode_ct_values(index: int, values: list[float]) -> bytes:
    """The `p003.ct` payload of servicer `index` from the 12 doubles of x~_i then ξ_i as Python
    floats (a batch turns all its rows into floats in one `tolist`, issue 29)."""
    return _CT.pack(VERSION, index, *values)


def decode_ct_values(payload: bytes) -> tuple[int, tuple[float, ...]]:
    """(index, the 12 values of x~_i then ξ_i as Python floats) of a `p003.ct` payload, checked as
    `decode_ct` checks it."""
    if len(payload) != _CT.size:
        raise ValueError(f"{CT_TYPE} payload must be {_CT.size} bytes, got {len(payload)}")
    version, index, *vals = _CT.unpack(payload)
    if version != VERSION:
        raise ValueError(f"{CT_TYPE} version {version}, expected {VERSION}")
    return index, tuple(vals)


def decode_ct(payload: bytes) -> CTPacket:
    index, vals = decode_ct_values(payload)
    v = np.array(vals, dtype=float)
    return CTPacket(index, v[:6], v[6:])
