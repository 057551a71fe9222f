"""Issue 11: the configuration / plant refactor keeps paper 002's truth bit for bit.

The checksums (sha256 over every `truth` payload, in order; bench/truth_checksums.py) were recorded
with the code of commit 4d6cdcd, before the refactor (`python bench/truth_checksums.py --duration
7200 deploy/scenarios/sabatini-20.toml deploy/scenarios/sabatini-20-beacon.toml
deploy/scenarios/sabatini-20-camera-filter.toml`, and the same with --duration 600). In-process
runs: the same node code as multi-process, which tests/test_backbone_run.py shows byte-identical.
sabatini-20 and sabatini-20-beacon have the same truth: beacons do not enter the controller.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from conftest import ROOT, SCENARIOS

sys.path.insert(0, str(ROOT / "bench"))
from truth_checksums import truth_sha256  # noqa: E402

BEFORE_600_S = {
    "sabatini-20": "89cbfa142ed61a8bcfb63c6185c3396fe10ddf51fbce6ecbdccf400b74228a8d",
    "sabatini-20-beacon": "89cbfa142ed61a8bcfb63c6185c3396fe10ddf51fbce6ecbdccf400b74228a8d",
    "sabatini-20-camera-filter": "540c024536829c8082214e546df4e87e96f5c1720c8fcf7e2824e2e2989da06e",
}
BEFORE_2_H = {
    "sabatini-20": "e819ffd017261b2bce96657032c82564677bd74a5c36ce3125ea368193a73eec",
    "sabatini-20-beacon": "e819ffd017261b2bce96657032c82564677bd74a5c36ce3125ea368193a73eec",
    "sabatini-20-camera-filter": "0d0e94695c5562ccd04d42e137f7c4ae501533192f30bac01e50cf9bea8e7f66",
}


@pytest.mark.parametrize("name", ["sabatini-20", "sabatini-20-beacon"])
def test_truth_of_the_first_ten_minutes_is_unchanged(name: str, tmp_path: Path) -> None:
    assert truth_sha256(str(SCENARIOS / f"{name}.toml"), 600.0, tmp_path / name) == BEFORE_600_S[name]


@pytest.mark.system
@pytest.mark.parametrize("name", sorted(BEFORE_2_H))
def test_truth_of_two_hours_is_unchanged(name: str, tmp_path: Path) -> None:
    assert truth_sha256(str(SCENARIOS / f"{name}.toml"), 7200.0, tmp_path / name) == BEFORE_2_H[name]
