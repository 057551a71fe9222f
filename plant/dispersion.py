"""Seeded initial conditions: deployment-like ROE dispersions (paper 002 section 4, Table 1 missing).

Paper 002's Table 1 is missing from the text; NOTES-002 asks for "tens of metres in da, de, di,
a few kilometres of along-track spread, without near-coincident pairs". The generator places
the spacecraft on evenly spaced along-track slots with a jitter (so no two start coincident) and
draws the other ROE from zero-mean Gaussians; callers can reject draws whose initial visibility
graph is not weakly connected.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Dispersion:
    count: int
    sigma_roe_m: tuple[float, float, float, float, float, float]  # a*(da, dl, dex, dey, dix, diy); dl sigma = slot jitter
    along_track_spacing_m: float
    mean_roe_m: tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def draw_roe(rng: np.random.Generator, d: Dispersion) -> np.ndarray:
    """(count, 6) ROE in metres: along-track slots (k - (N-1)/2) * spacing + jitter, the rest Gaussian."""
    sigma = np.asarray(d.sigma_roe_m, dtype=float)
    roe = rng.normal(0.0, 1.0, size=(d.count, 6)) * sigma + np.asarray(d.mean_roe_m, dtype=float)
    slots = (np.arange(d.count) - (d.count - 1) / 2.0) * d.along_track_spacing_m
    roe[:, 1] += slots[rng.permutation(d.count)]
    return roe
