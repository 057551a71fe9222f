"""Which gathering law an agent runs (paper 001 sec. III, Table 3), latched per agent.

natural gathering (far)  -> g_far + l            until |r| < r_middle or t > t_natural
artificial gathering     -> g_free + l + d        until |r| < r_inner
shaping ball             -> g_planar + g_phase + l + d
A layer once left is never re-entered (latching: an agent thrown back out by a collision stays
in the later layer, so the far field, singular near the origin, is never re-armed).
"""
from __future__ import annotations

from enum import IntEnum


class Layer(IntEnum):
    FAR = 0
    NEAR = 1
    SHAPING = 2


def next_layer(current: Layer, radius_m: float, t_s: float, r_middle_m: float, r_inner_m: float,
               t_natural_s: float) -> Layer:
    """The latched layer after this step's test (layers only move inwards)."""
    if radius_m < r_inner_m:
        return Layer.SHAPING
    if current == Layer.FAR and (radius_m < r_middle_m or t_s > t_natural_s):
        return Layer.NEAR
    return current
