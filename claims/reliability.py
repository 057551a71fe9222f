"""docs/reliability.md "Lockstep does not depend on load": the lockstep run of a camera + link
scenario undisturbed and beside 3 CPU burners per core (`tests/test_lockstep_load.py`
`lockstep_quiet_and_loaded`, the system test's own function). Tier `bench`: its wall times and the
load are this machine's at that moment (presence and shape only); the deliveries and "identical"
are exact. The promises themselves are the system tests named in the table (CI)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

from swarmhil.claims.missions import test_module
from swarmhil.claims.model import Claim, Row, Source, Table, Tol

DOC = "docs/reliability.md"
SHAPE = Tol(shape_only=True)


def _lockstep(_get: Any) -> dict[str, Any]:
    m = test_module("test_lockstep_load")
    with tempfile.TemporaryDirectory(prefix="claims-lockstep-") as d:
        r = m.lockstep_quiet_and_loaded(Path(d))
    q, lo = r["quiet"], r["loaded"]
    same = all(lo["raw"].get(t) == q["raw"][t] for t in m.compared_topics(q["raw"]))
    return {"wall_quiet_s": float(q["summary"]["wall_s"]), "wall_loaded_s": float(lo["summary"]["wall_s"]),
            "deliveries": int(q["summary"]["channel"]["totals"]["rx_messages"]), "burners": lo["burners"],
            "identical": "identical" if same else "differ", "cores": os.cpu_count() or 0,
            **{f"load_{c}_{e}": r[c][f"load_{e}"] for c in ("quiet", "loaded") for e in ("start", "end")}}


SOURCES = [Source("rel.lockstep", "bench", _lockstep,
                  "tests/test_lockstep_load.py lockstep_quiet_and_loaded (2 x 20 steps, multi-process, 6 burners)")]


def _c(id_: str, key: str, tol: Tol, what: str, fmt: str = ".0f") -> Claim:
    return Claim(f"rel.lockstep.{id_}", "rel.lockstep", lambda s: s[key], tol, what, fmt)


CLAIMS = [
    _c("wall-quiet", "wall_quiet_s", SHAPE, "wall time of the undisturbed run [s]"),
    _c("wall-loaded", "wall_loaded_s", SHAPE, "wall time beside the burners [s]"),
    *[_c(f"load-{c}-{e}", f"load_{c}_{e}", SHAPE, f"load average (1 min) at the {e} of the {c} run [-]")
      for c in ("quiet", "loaded") for e in ("start", "end")],
    _c("burners", "burners", SHAPE, "CPU burners (3 per core)", "d"),
    _c("cores", "cores", SHAPE, "cores of the machine", "d"),
    _c("deliveries", "deliveries", Tol(), "ISL deliveries of the run (rx messages)", "d"),
    _c("identical", "identical", Tol(), "truth, commands and ISL deliveries of the two runs byte-identical", ""),
]
T = "`tests/test_lockstep_load.py::"
TABLES = [Table("reliability-lockstep", DOC, ("promise", "test"), measured=(0,), rows=(
    Row(("An agent 7 s late for one step (longer than the old 5 s timeout; its token up) is waited for: no missed "
         "deadline, no death, truth byte-identical to the in-process run.", T + "test_a_slow_live_agent_is_waited_for`"),
        params=("7", "5")),
    Row(("A step open longer than `stall_timeout_s` (2 s in the test) is one error Event `lockstep_stall`; the late "
         "agent is dropped (dead, reason the stall); the run completes.",
         T + "test_a_stall_is_an_error_event_after_the_stall_timeout`"), params=("2",)),
    Row(("The same lockstep run of a camera + link scenario (4 agents rendering 1080 px frames with the EKF, link "
         "channel with beacons, 20 steps), undisturbed and beside 3 CPU burners per core (`python3 -c 'while True: "
         "pass'`, started and killed by PID), gives byte-identical truth, commands and ISL deliveries. Measured "
         "(`swarmhil claims --bench --only rel.`, the test's own function, on the shared {rel.lockstep.cores}-core "
         "machine, one invocation): {rel.lockstep.wall-quiet} s wall without burners (load average "
         "{rel.lockstep.load-quiet-start} → {rel.lockstep.load-quiet-end} from other work), "
         "{rel.lockstep.wall-loaded} s beside the {rel.lockstep.burners} burners (load average "
         "{rel.lockstep.load-loaded-start} → {rel.lockstep.load-loaded-end}), {rel.lockstep.deliveries} "
         "deliveries, {rel.lockstep.identical}: the wall time follows the machine's whole load, the results do not.",
         T + "test_lockstep_under_cpu_load_is_bit_identical` (system)"), params=("4", "1080", "20", "3")),
))]
