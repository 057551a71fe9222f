"""Seeded initial states for the paper-000 capture scenarios (paper §4, NOTES-000).

`capture-10.toml` / `capture-20.toml` hold seed 1's draw explicitly. For a sweep over seeds this
rewrites a scenario's spacecraft positions and attitudes with seed s's draw, the room loop's rule
(`tests/missions/test_p000_closed_loop.run_capture`): positions uniform in [−10, 10]³, ≥ 2 m apart,
outside the R_buffer shell of the target at t = 0; then attitudes, normalised Gaussian 4-vectors;
both from `numpy.random.default_rng(s)`. `[run].seed` becomes s too (the sensor noise key).

    python -m swarmhil.missions.p000_capture.seeds deploy/scenarios/capture-20.toml 2 runs/capture-20-s2.toml
"""
from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

import numpy as np

from swarmhil.missions.p000_capture.fsw import quaternion as quat
from swarmhil.missions.p000_capture.contract import Ellipsoid, signed_distance


def initial_state(n: int, semi_axes_m, seed: int, r_buffer_m: float = 1.0,
                  half_box_m: float = 10.0, min_sep_m: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """(positions (n, 3), attitudes (n, 4)) of seed's draw; the target at the origin, unrotated."""
    rng = np.random.default_rng(seed)
    ell = Ellipsoid(np.zeros(3), np.eye(3), np.asarray(semi_axes_m, dtype=float))
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform(-half_box_m, half_box_m, 3)
        if signed_distance(ell, p) <= r_buffer_m:
            continue
        if all(np.linalg.norm(p - o) >= min_sep_m for o in pts):
            pts.append(p)
    q = np.array([quat.normalise(rng.normal(size=4)) for _ in range(n)])
    return np.array(pts), q


def seeded_scenario(text: str, seed: int) -> str:
    """The scenario TOML `text` with seed's initial state and `[run].seed = seed`."""
    doc = tomllib.loads(text)
    targets = [b for b in doc.get("body", []) if b.get("kind") == "target"]
    if len(targets) != 1 or (targets[0].get("shape") or {}).get("kind") != "ellipsoid":
        raise ValueError("the scenario needs exactly one [[body]] of kind 'target' with an ellipsoid shape")
    body = targets[0]
    n = len(doc["spacecraft"])
    r, q = initial_state(n, body["shape"]["semi_axes_m"], seed)
    pos, att = iter(r.tolist()), iter(q.tolist())
    text = re.sub(r"(?m)^position_m = \[.*\]$", lambda _: f"position_m = {next(pos)}", text)
    text = re.sub(r"(?m)^attitude_q = \[.*\]$", lambda _: f"attitude_q = {next(att)}", text)
    text, k = re.subn(r"(?m)^seed = \d+", f"seed = {seed}", text, count=1)
    if k != 1 or next(pos, None) is not None or next(att, None) is not None:
        raise ValueError("the scenario does not hold one position_m and attitude_q per spacecraft and a [run] seed")
    return text


def main(argv: list[str]) -> int:
    if len(argv) != 3 or not argv[1].isdigit():
        print("usage: python -m swarmhil.missions.p000_capture.seeds SCENARIO.toml SEED OUT.toml", file=sys.stderr)
        return 2
    try:
        out = seeded_scenario(Path(argv[0]).read_text(), int(argv[1]))
    except (OSError, ValueError, KeyError, tomllib.TOMLDecodeError) as exc:
        print(f"missions.p000_capture.seeds: {exc}", file=sys.stderr)
        return 2
    Path(argv[2]).write_text(out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
