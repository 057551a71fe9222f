"""The inter-satellite-link message of paper 004: a servicer's u_i and theta_hat_i, every step.

The observer (eq. 26) needs the neighbours' control inputs u_j and the adaptation law (eq. 28)
their weights theta_hat_j, so each servicer broadcasts both once per step. Layout, little-endian:

    offset size  field
    0      2     magic b"P4"
    2      1     version (1)
    3      1     bytes per weight: 4 (float32) or 8 (float64)
    4      2     n, number of weights (103)
    6      4     step (uint32)
    10     8     t_s, simulation time of the state (float64)
    18     24    u_i, m/s^2 (3 x float64)
    42     n*w   theta_hat_i (float32 or float64)

18 + 24 + 412 = 454 bytes with float32 weights, 866 with float64.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

PACKET_TYPE = "p004.state"
MAGIC = b"P4"
VERSION = 1
_HEADER = struct.Struct("<2sBBHId")
_U = struct.Struct("<3d")


@dataclass(frozen=True)
class StatePacket:
    """One servicer's broadcast for step `step`."""

    step: int
    t_s: float
    accel_mps2: np.ndarray  # u_i, (3,)
    theta: np.ndarray  # theta_hat_i, (n,)


def encode(pkt: StatePacket, weight_bytes: int = 4) -> bytes:
    """StatePacket -> bytes (layout in the module docstring)."""
    if weight_bytes not in (4, 8):
        raise ValueError(f"weight_bytes must be 4 or 8, got {weight_bytes}")
    theta = np.asarray(pkt.theta, dtype=float).ravel()
    u = np.asarray(pkt.accel_mps2, dtype=float).ravel()
    if u.shape != (3,):
        raise ValueError(f"accel_mps2 has shape {u.shape}, expected (3,)")
    if not (np.isfinite(theta).all() and np.isfinite(u).all()):
        raise ValueError("refusing to encode a non-finite u or theta")
    dtype = "<f4" if weight_bytes == 4 else "<f8"
    head = _HEADER.pack(MAGIC, VERSION, weight_bytes, theta.size, int(pkt.step), float(pkt.t_s))
    return head + _U.pack(*u.tolist()) + theta.astype(dtype).tobytes()  # tolist: the same doubles, packed without numpy scalars


def decode(payload: bytes) -> StatePacket:
    """bytes -> StatePacket; raises ValueError naming what is wrong."""
    if len(payload) < _HEADER.size + _U.size:
        raise ValueError(f"p004 packet too short: {len(payload)} bytes")
    magic, version, wbytes, n, step, t_s = _HEADER.unpack_from(payload, 0)
    if magic != MAGIC or version != VERSION:
        raise ValueError(f"not a p004 v{VERSION} packet: magic {magic!r}, version {version}")
    if wbytes not in (4, 8):
        raise ValueError(f"p004 packet: bytes per weight {wbytes}, expected 4 or 8")
    expected = _HEADER.size + _U.size + n * wbytes
    if len(payload) != expected:
        raise ValueError(f"p004 packet: {len(payload)} bytes, expected {expected} for {n} weights")
    u = np.array(_U.unpack_from(payload, _HEADER.size))
    theta = np.frombuffer(payload, dtype="<f4" if wbytes == 4 else "<f8",
                          offset=_HEADER.size + _U.size, count=n).astype(float)
    if not (np.isfinite(u).all() and np.isfinite(theta).all()):
        raise ValueError("p004 packet carries a non-finite value")
    return StatePacket(step=int(step), t_s=float(t_s), accel_mps2=u, theta=theta)
