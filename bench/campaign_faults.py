"""Minor page faults and CPU of campaign runs inside one Dask worker, with Dask's default worker
environment (`MALLOC_TRIM_THRESHOLD_=65536`) or with the campaign's (`unset`, glibc's defaults):
docs/performance.md, "The page faults were Dask's".

    python bench/campaign_faults.py default 2
    python bench/campaign_faults.py unset 2
"""
from __future__ import annotations

import argparse
import logging
import os
import resource
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def one_run(scenario: str, seed: int, out: str) -> dict[str, Any]:
    """`run_seed` (24 h, metrics, no recording kept) with getrusage of the worker around it."""
    from swarmhil.deploy.campaign import run_seed

    r0 = resource.getrusage(resource.RUSAGE_SELF)
    row = run_seed(scenario, [], seed, out, None, True, False)
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    return {"seed": seed, "status": row["status"], "minflt": r1.ru_minflt - r0.ru_minflt,
            "user_s": round(r1.ru_utime - r0.ru_utime, 2), "system_s": round(r1.ru_stime - r0.ru_stime, 2),
            "MALLOC_TRIM_THRESHOLD_": os.environ.get("MALLOC_TRIM_THRESHOLD_")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("default", "unset"))
    ap.add_argument("runs", type=int, nargs="?", default=2)
    ap.add_argument("--scenario", default=str(ROOT / "deploy/scenarios/sabatini-20.toml"))
    a = ap.parse_args()
    import dask.config
    from dask.distributed import Client, LocalCluster

    from swarmhil.deploy.campaign import LOCAL_WORKER_ENV

    with dask.config.set({} if a.mode == "default" else LOCAL_WORKER_ENV):
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.WARNING)
    client = Client(cluster)
    try:
        out = tempfile.mkdtemp(prefix="swarmhil-faults-")
        for seed in range(a.runs):
            print(a.mode, client.submit(one_run, a.scenario, seed, out, pure=False).result(), flush=True)
    finally:
        client.close()
        cluster.close()


if __name__ == "__main__":
    main()
