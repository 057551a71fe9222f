"""docs/determinism.md's drift table is the rendering of the committed measurements (issue 24).

Each row comes from docs/data/kernel-drift/NAME.json, written by bench/kernel_drift.py; the page
must hold exactly `kernel_drift.markdown_table` of them, in the page's order, so a number on the page
cannot differ from what the tool measured.
"""
from __future__ import annotations

import json
import re
import sys

from conftest import ROOT

sys.path.insert(0, str(ROOT / "bench"))
from kernel_drift import markdown_table  # noqa: E402

DOC = ROOT / "docs" / "determinism.md"
DATA = ROOT / "docs" / "data" / "kernel-drift"


def test_the_drift_table_is_the_rendering_of_the_measurements() -> None:
    text = DOC.read_text()
    m = re.search(r"<!-- kernel-drift table[^>]*-->\n(.*?)\n<!-- /kernel-drift table -->", text, re.S)
    assert m, "docs/determinism.md has no kernel-drift table between its markers"
    rows = [line.split("|")[1].strip() for line in m.group(1).splitlines()[2:]]
    files = sorted(p.stem for p in DATA.glob("*.json"))
    assert sorted(rows) == files, "every measurement has a row and every row a measurement"
    results = {}
    for name in rows:
        doc = json.loads((DATA / f"{name}.json").read_text())
        results[name] = doc["results"][name]
        assert doc["alternate_kernels"] == {"OPENBLAS_CORETYPE": "Sandybridge", "NPY_DISABLE_CPU_FEATURES": "X86_V3"}
    assert m.group(1) == markdown_table(results)
