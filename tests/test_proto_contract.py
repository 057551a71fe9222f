"""The committed generated code matches bus/swarmhil.proto (DESIGN.md: checked in CI)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import ROOT


def test_generated_code_matches_proto(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", "-I", str(ROOT / "bus"), f"--python_out={tmp_path}",
                    f"--pyi_out={tmp_path}", str(ROOT / "bus" / "swarmhil.proto")], check=True)
    for name in ("swarmhil_pb2.py", "swarmhil_pb2.pyi"):
        assert (tmp_path / name).read_text() == (ROOT / "bus" / name).read_text(), f"bus/{name} is stale: run `make proto`"


def test_every_message_starts_with_header() -> None:
    from swarmhil.bus import swarmhil_pb2 as pb

    exempt = {"Header", "Vector3", "Quaternion", "BodyState", "RelativeState", "ScenePose", "NeighbourDecision",
              "TrackEstimate", "LinkCounter", "Beacon", "Measurement"}  # parts of messages
    for name, desc in pb.DESCRIPTOR.message_types_by_name.items():
        if name in exempt:
            continue
        f = desc.fields_by_number.get(1)
        assert f is not None and f.name == "header" and f.message_type.name == "Header", name
    assert pb.DESCRIPTOR.package == "swarmhil.v1"
