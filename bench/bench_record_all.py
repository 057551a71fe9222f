"""Every packet against the truth only, in-process, side by side in one invocation.

    python bench/bench_record_all.py [--hours 24] [--repeats 2] [--zstd] [--no-per-agent] [SCENARIO ...]

For each scenario (default sabatini-20) runs `run_in_process` three ways, each in a fresh Python
process, interleaved repeat by repeat: the batch mode recording the truth only (`--record truth`),
the batch mode recording every packet (`--record all`, deploy/batch_packets.py) and the per-agent
path recording every packet (`opts batch = false`: one agent node per spacecraft, as before the
batch mode recorded packets). It prints each run's whole-process CPU seconds (start-up included;
the recorder's compression thread included) and wall seconds, the messages and bytes recorded, then
the medians and the ratios every-packet batch / truth-only batch and per-agent / every-packet batch,
and how many record plans the every-packet batch run built (bus/mcap_writer.py BulkRecords: the
steps whose layout was new). `--zstd`: the every-packet recording's chunks compressed again at
several zstd levels (CPU and size), what the recorder's level is chosen by.
The machine is shared: only ratios measured in one invocation mean anything; the load average is
printed with them. The three runs must give the same total dV (printed and checked).
`--no-per-agent`: the two batch runs only (a long scenario whose per-agent run would take most of
the invocation).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CODE = r"""
import json, sys, time
from pathlib import Path
from swarmhil.bus import mcap_writer
from swarmhil.deploy.launcher import run_in_process
from swarmhil.deploy.scenario import load_scenario
made = []
_init = mcap_writer.BulkRecords.__init__
def _kept(self, *a, **k):
    _init(self, *a, **k)
    made.append(self)
mcap_writer.BulkRecords.__init__ = _kept
sc = load_scenario(sys.argv[1])
if float(sys.argv[2]) > 0:
    sc = sc.with_overrides(duration_s=float(sys.argv[2]))
t0 = time.perf_counter()
res = run_in_process(sc, Path(sys.argv[3]), 'bench', record=sys.argv[4], opts={'batch': sys.argv[5] == 'batch'})
wall = time.perf_counter() - t0
size = (Path(sys.argv[3]) / 'run.mcap').stat().st_size
print(json.dumps({'cpu_s': time.process_time(), 'wall_s': wall, 'dv': res.summary['delta_v_total_mps'],
                  'messages': res.summary['recording']['messages'], 'bytes': size, 'batch': res.summary['batch'],
                  'steps': sc.steps, 'plans': sum(r.built for r in made)}))
"""

MODES = (("truth-only batch", "truth", "batch"), ("every-packet batch", "all", "batch"),
         ("every-packet per-agent", "all", "agents"))


def one(scenario: str, seconds: float, out: Path, record: str, path: str) -> dict:
    root = Path(__file__).resolve().parent.parent
    p = subprocess.run([sys.executable, "-c", CODE, scenario, str(seconds), str(out), record, path],
                       cwd=root, capture_output=True, text=True, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def zstd_levels(path: Path) -> None:
    """CPU and size of the recording's chunks (uncompressed) compressed at several zstd levels."""
    import time

    import zstandard
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        chunks = [zstandard.ZstdDecompressor().decompress(r.data, max_output_size=r.uncompressed_size)
                  for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    raw = sum(len(c) for c in chunks)
    print(f"{path.parent.name}: {len(chunks)} chunks, {raw / 1e6:.1f} MB uncompressed")
    for level in (3, 1, -1, -3, -7):
        z = zstandard.ZstdCompressor(level=level)
        c0 = time.process_time()
        size = sum(len(z.compress(c)) for c in chunks)
        print(f"  zstd level {level}: {time.process_time() - c0:.2f} s CPU, {size / 1e6:.1f} MB", flush=True)


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser()
    ap.add_argument("scenarios", nargs="*", default=[str(root / "deploy/scenarios/sabatini-20.toml")])
    ap.add_argument("--hours", type=float, default=24.0, help="simulated hours (0: the scenario's own duration)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--zstd", action="store_true", help="also: the every-packet recording's chunks at several zstd levels")
    ap.add_argument("--no-per-agent", action="store_true", help="the two batch runs only")
    a = ap.parse_args()
    modes = MODES[:2] if a.no_per_agent else MODES
    load0 = Path("/proc/loadavg").read_text().split()[:3]
    with tempfile.TemporaryDirectory() as d:
        for scenario in a.scenarios:
            name = Path(scenario).stem
            res: dict[str, list[dict]] = {m: [] for m, *_ in modes}
            for r in range(a.repeats):
                for label, record, path in modes:
                    x = one(str(Path(scenario).resolve()), a.hours * 3600.0, Path(d) / f"{name}-{r}-{record}-{path}",
                            record, path)
                    res[label].append(x)
                    print(f"{name} #{r} {label}: CPU {x['cpu_s']:.2f} s, wall {x['wall_s']:.2f} s, {x['messages']} messages, "
                          f"{x['bytes'] / 1e6:.1f} MB, batch {x['batch']['used']}, dV {x['dv']!r}", flush=True)
            cpu = {k: statistics.median(x["cpu_s"] for x in v) for k, v in res.items()}
            t, b = cpu[MODES[0][0]], cpu[MODES[1][0]]
            p = cpu.get(MODES[2][0])
            same = len({x["dv"] for v in res.values() for x in v}) == 1
            agents = "" if p is None else f", every-packet per-agent {p:.2f} s"
            ratio = "" if p is None else f", per-agent / every-packet batch = {p / b:.2f}x"
            print(f"{name} median CPU: truth-only batch {t:.2f} s, every-packet batch {b:.2f} s{agents}; every-packet "
                  f"batch / truth-only batch = {b / t:.2f}x{ratio}; total dV identical: {same}", flush=True)
            x = res["every-packet batch"][0]
            print(f"{name} every-packet batch: {x['plans']} record plans built for {x['steps']} steps", flush=True)
            if a.zstd:
                zstd_levels(Path(d) / f"{name}-0-all-batch" / "run.mcap")
    load1 = Path("/proc/loadavg").read_text().split()[:3]
    print(f"load average at start {' '.join(load0)}, at end {' '.join(load1)}")


if __name__ == "__main__":
    main()
