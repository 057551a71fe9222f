"""Monte Carlo campaigns (issue 16): N seeded batch runs of one scenario, one table row per run.

`swarmhil campaign` (deploy/cli_campaign.py) is the command; this module is what runs on the
workers and what assembles the results, so it imports nothing heavy at module level.

Layout of a campaign directory OUT:

    OUT/campaign.json          the campaign's parameters (scenario, --set, seeds, duration)
    OUT/rows/seed-000007.json  one finished run (ok or failed): its table row; written atomically
    OUT/runs/seed-000007/      that run's run.mcap and summary.json (summary["metrics"] with metrics)
    OUT/campaign.parquet, OUT/campaign.csv, OUT/report.md, OUT/report.html

A seed whose row file exists is finished and is not run again (resume); a run that raised is a
row with `status = "error"` and its `error`, re-run only with `retry_failed`.
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from swarmhil.deploy.fault_draws import FaultDrawError, draw_faults, load_fault_draws, with_drawn_faults

__all__ = ["FaultDrawError", "draw_faults", "load_fault_draws", "run_campaign", "with_drawn_faults"]  # re-exported for the command

ROW_DIR = "rows"
RUN_DIR = "runs"
FIRST_COLUMNS = ("seed", "status", "error", "wall_s", "cpu_s", "delta_v_total_mps", "steps", "dead_agents_count",
                 "rejected_packets")


def row_path(out: Path, seed: int) -> Path:
    return Path(out) / ROW_DIR / f"seed-{seed:06d}.json"


def run_dir(out: Path, seed: int) -> Path:
    return Path(out) / RUN_DIR / f"seed-{seed:06d}"


def finished_seeds(out: Path, retry_failed: bool = False) -> set[int]:
    """Seeds with a row file (and, with retry_failed, only those that succeeded)."""
    done: set[int] = set()
    d = Path(out) / ROW_DIR
    if not d.is_dir():
        return done
    for p in d.glob("seed-*.json"):
        try:
            row = json.loads(p.read_text())
        except (OSError, ValueError):
            continue  # a torn file cannot exist (atomic writes), but never trust it: run again
        if retry_failed and row.get("status") != "ok":
            continue
        done.add(int(row["seed"]))
    return done


def flatten_scalars(d: dict[str, Any], prefix: str = "", skip: Sequence[str] = ("config",)) -> dict[str, Any]:
    """Every scalar (number, bool, str, None) of a nested dict, as `a.b.c` columns; lists are skipped
    (their length is kept as `a.b_count`), the resolved `config` too (it is in every summary.json)."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if not prefix and k in skip:
            continue
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten_scalars(v, f"{name}.", skip))
        elif isinstance(v, (list, tuple)):
            out[f"{name}_count"] = len(v)
        elif v is None or isinstance(v, (bool, int, float, str)):
            out[name] = v
    return out


def summary_row(summary: dict[str, Any]) -> dict[str, Any]:
    row = flatten_scalars(summary)
    # the per-spacecraft dicts become columns too (delta_v_mps.sc01, ...); dead agents also as a count
    row["dead_agents_count"] = len(summary.get("dead_agents") or {})
    return row


def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def run_seed(scenario: str, sets: Sequence[str], seed: int, out: str, duration_s: float | None = None,
             metrics: bool = True, keep_recording: bool = True, record: str = "truth",
             faults: str | None = None) -> dict[str, Any]:
    """One campaign run (on a worker): the in-process run of SCENARIO with --set SETS and this seed
    (record="truth": the batch mode where the scenario allows it, deploy/batch.py; "all": every
    message, one agent node per spacecraft), then its metrics (dashboards/metrics.py, as
    `swarmhil report` computes them, without figures). `faults`: a faults file (deploy/fault_draws.py):
    the run flies with the faults drawn for its seed, and its row carries them with their recovery
    (`faults`, JSON). Writes and returns its row; never raises for a failed run (the row carries the
    error)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    t0, c0 = time.monotonic(), time.thread_time()
    row: dict[str, Any] = {"seed": int(seed), "status": "ok", "error": None}
    rdir = run_dir(Path(out), seed)
    try:
        from swarmhil.deploy.launcher import run_in_process  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
        from swarmhil.deploy.scenario import load_scenario  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        sc = load_scenario(scenario, list(sets)).with_overrides(seed=int(seed), duration_s=duration_s)
        drawn: list[dict[str, Any]] = []
        hold: float | None = None
        if faults:
            draws = load_fault_draws(faults, sc.ids)
            drawn, hold = draw_faults(draws, sc.ids, int(seed)), draws.recovery.hold_s
            sc = with_drawn_faults(sc, drawn).with_overrides(seed=int(seed), duration_s=duration_s)
            row["faults_n"] = len(drawn)
        res = run_in_process(sc, rdir, f"{_safe(sc.name)}-seed{int(seed)}", progress=False, record=record,
                             keep_truth=metrics)
        summary = res.summary
        if metrics:
            from swarmhil.dashboards.report import write_report  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
            from swarmhil.dashboards.run_metrics import write_metrics  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
            from swarmhil.plant.sensors import CameraGeometry  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

            cam = CameraGeometry(sc.camera["detection_range_m"], sc.camera["image_px"], sc.camera["focal_px"])
            if res.truth is not None:  # the arrays the run kept: no read-back of the recording
                write_metrics(rdir, res.truth, cam)
            else:
                write_report(rdir, cam=cam, figures=False)
            summary = json.loads((rdir / "summary.json").read_text())
        row.update(summary_row(summary))
        if faults:
            from swarmhil.dashboards.sections.faults import drawn_fault_recovery  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

            row["faults"] = json.dumps(drawn_fault_recovery(drawn, sc.resolved(), rdir, hold) if metrics else drawn)
        if not keep_recording:
            (rdir / "run.mcap").unlink(missing_ok=True)
    except Exception as exc:  # noqa: BLE001 - a failed run is a row, not a lost campaign
        row["status"] = "error"
        row["error"] = f"{type(exc).__name__}: {exc}"
    row["seed"] = int(seed)
    row["wall_s"] = time.monotonic() - t0
    row["cpu_s"] = time.thread_time() - c0  # this run's CPU time (the worker thread's): the load-free cost
    _write_atomic(row_path(Path(out), seed), json.dumps(row, default=_json_default))
    return row


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "_-." else "_" for c in name) or "campaign"


def _json_default(v: Any) -> Any:
    try:
        return float(v)
    except (TypeError, ValueError):
        return str(v)


# --- executors ------------------------------------------------------------------------------------------
# Dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536 (distributed.yaml, to give memory
# back to the OS). Setting it also turns off glibc's sliding mmap threshold, so every numpy
# temporary above 128 KiB is a fresh mmap and munmap: 408 k minor page faults and 1.2-1.5 s of
# system time per 24 h sabatini-20 run, against 7-44 k and 0.4-0.5 s without it (utime 4.3-5.4 ->
# 3.9-4.5 s; docs/performance.md). A campaign run's memory is small and short-lived, so the
# LocalCluster's workers get glibc's defaults; a cluster given by --scheduler keeps its own setting.
LOCAL_WORKER_ENV = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def execute(fn: Callable[..., dict[str, Any]], calls: dict[Any, tuple], *, executor: str = "local", jobs: int = 2,
            scheduler: str | None = None, on_row: Callable[[Any, dict[str, Any]], None] | None = None,
            lost: Callable[[Any, str], dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """fn(*calls[key]) for every key on the executor (`local`: a process pool of `jobs`; `dask`: a
    LocalCluster of `jobs` single-threaded workers on 127.0.0.1, or the cluster at `scheduler`), for
    `swarmhil campaign` (keys are seeds) and `swarmhil sweep` (keys are cases). Rows in completion
    order, each also given to on_row(key, row); a task that raised (or whose worker died) is the
    row lost(key, error) (default: a failed campaign row of seed `key`)."""
    rows: list[dict[str, Any]] = []
    keys = list(calls)
    lost = lost or (lambda k, err: {"seed": k, "status": "error", "error": err})
    if not keys:
        return rows

    def done(key: Any, get: Callable[[], dict[str, Any]]) -> None:
        try:
            r = get()
        except Exception as exc:  # noqa: BLE001 - a worker lost: the task is a failed row
            r = lost(key, f"{type(exc).__name__}: {exc}")
        rows.append(r)
        if on_row:
            on_row(key, r)

    if executor == "dask":
        from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        dd = require("dask.distributed", "--executor dask")
        Client, LocalCluster, as_completed = dd.Client, dd.LocalCluster, dd.as_completed
        dd_config = require("dask.config", "--executor dask")

        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:  # one single-threaded worker process per job, everything on loopback, no dashboard
            import logging

            logging.getLogger("distributed").setLevel(logging.WARNING)  # its scheduler's INFO lines, in this process
            with dd_config.set(LOCAL_WORKER_ENV):  # read by each Nanny when it is made (and kept for restarts)
                cluster = LocalCluster(n_workers=max(1, jobs), threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=None, protocol="tcp://", silence_logs=logging.WARNING)
            client = Client(cluster)
        try:
            futs = {client.submit(fn, *calls[k], pure=False): k for k in keys}
            for f in as_completed(futs):
                done(futs[f], f.result)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        return rows
    if executor == "local":
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed as cf_completed

        with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=mp.get_context("spawn")) as pool:
            futs = {pool.submit(fn, *calls[k]): k for k in keys}
            for f in cf_completed(futs):
                done(futs[f], f.result)
        return rows
    raise ValueError(f"unknown executor {executor!r}: local or dask")


# --- the table and the report ---------------------------------------------------------------------------
def load_rows(out: Path, seeds: Iterable[int] | None = None) -> list[dict[str, Any]]:
    want = None if seeds is None else set(int(s) for s in seeds)
    rows = []
    for p in sorted((Path(out) / ROW_DIR).glob("seed-*.json")):
        r = json.loads(p.read_text())
        if want is None or int(r["seed"]) in want:
            rows.append(r)
    return sorted(rows, key=lambda r: r["seed"])


def _columns(rows: list[dict[str, Any]], first: Sequence[str] = FIRST_COLUMNS) -> list[str]:
    seen: dict[str, None] = {c: None for c in first}
    for r in rows:
        for k in r:
            seen.setdefault(k, None)
    return list(seen)


def _column_values(rows: list[dict[str, Any]], col: str) -> list[Any]:
    vals = [r.get(col) for r in rows]
    kinds = {type(v) for v in vals if v is not None}
    if kinds and kinds <= {int, float} and float in kinds:
        vals = [None if v is None else float(v) for v in vals]  # ints and floats in one column: floats
    elif len(kinds) > 1:
        vals = [None if v is None else str(v) for v in vals]  # anything else mixed: text
    return vals


def write_table(out: Path, rows: list[dict[str, Any]], name: str = "campaign",
                first: Sequence[str] = FIRST_COLUMNS) -> tuple[Path, Path]:
    """OUT/<name>.parquet and OUT/<name>.csv: one row per run, the same columns (`first` first)."""
    import csv

    from swarmhil.bus.optional import require  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    pa = require("pyarrow", "the campaign table (Parquet)")
    pq = require("pyarrow.parquet", "the campaign table (Parquet)")

    cols = _columns(rows, first)
    data = {c: _column_values(rows, c) for c in cols}
    arrays = {c: pa.array(v, type=pa.string() if all(x is None for x in v) else None) for c, v in data.items()}
    pq.write_table(pa.table(arrays), Path(out) / f"{name}.parquet")
    with open(Path(out) / f"{name}.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for i in range(len(rows)):
            w.writerow(["" if data[c][i] is None else data[c][i] for c in cols])
    return Path(out) / f"{name}.parquet", Path(out) / f"{name}.csv"


def mean_ci95(x: Sequence[float]) -> dict[str, float | int | None]:
    """Mean, sample standard deviation and the 95 % confidence interval of the mean (Student t)."""
    v = [float(a) for a in x if a is not None and math.isfinite(float(a))]
    n = len(v)
    if n == 0:
        return {"n": 0, "mean": None, "std": None, "ci95_low": None, "ci95_high": None, "min": None, "max": None}
    m = sum(v) / n
    if n == 1:
        return {"n": 1, "mean": m, "std": None, "ci95_low": None, "ci95_high": None, "min": m, "max": m}
    from scipy.stats import t as student_t

    sd = math.sqrt(sum((a - m) ** 2 for a in v) / (n - 1))
    h = float(student_t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return {"n": n, "mean": m, "std": sd, "ci95_low": m - h, "ci95_high": m + h, "min": min(v), "max": max(v)}


REPORT_METRICS = (
    ("delta_v_total_mps", "total dV [m/s]"),
    ("metrics.connectivity.weakly_connected_fraction", "weakly connected, fraction of steps"),
    ("metrics.connectivity.weakly_connected_fraction_steady", "weakly connected, fraction of steady steps"),
    ("metrics.connectivity.max_components", "max weakly connected components"),
    ("metrics.closest_approach.all_pairs.distance_m", "closest approach, all pairs [m]"),
    ("metrics.closest_approach.visible_pairs.distance_m", "closest approach, visible pairs [m]"),
    ("dead_agents_count", "dead agents"),
    ("rejected_packets", "rejected packets"),
    ("wall_s", "wall per run [s]"),
    ("cpu_s", "CPU per run [s]"),
)


def fault_outcome(f: dict[str, Any]) -> str:
    """A drawn fault's outcome (dashboards/sections/faults.py `judge`, OUTCOMES): a link fault's on
    the link graph of its deliveries, any other's on the camera-visibility graph; "not judged" where
    the run has no such graph (or did not record the link's deliveries)."""
    key = "link_outcome" if str(f["kind"]).startswith("link_") else "outcome"
    return str(f.get(key) or "not judged")


COUNTED = ("never split", "split and recovered", "not recovered")  # the outcomes a fault campaign counts


def fault_stats(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per fault kind, over the ok runs of a fault campaign: the faults drawn; how many the swarm
    never split under, split under and recovered from (whole again and staying so for the run's
    hold_s), split under and did not recover from by the run's end, and could not be judged
    (`fault_outcome`); the fraction of the judged ones in each of the three with its Wilson 95 %
    interval (scipy.stats.binomtest); the time to the held reconnection of the recovered ones and
    the swarm's ΔV in the fault's window."""
    from scipy.stats import binomtest

    by_kind: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        if r.get("status") == "ok":
            for f in json.loads(r.get("faults") or "[]"):
                by_kind.setdefault(f["kind"], []).append(f)
    out: dict[str, dict[str, Any]] = {}
    for kind, fs in sorted(by_kind.items()):
        outcome = [fault_outcome(f) for f in fs]
        judged = sum(o in COUNTED for o in outcome)
        s: dict[str, Any] = {"drawn": len(fs), "judged": judged, "not judged": len(fs) - judged}
        for name in COUNTED:
            k = outcome.count(name)
            ci = binomtest(k, judged).proportion_ci(0.95, "wilson") if judged else None
            s[name] = {"n": k, "fraction": k / judged if judged else None,
                       "ci95_low": None if ci is None else float(ci.low), "ci95_high": None if ci is None else float(ci.high)}
        if any("baseline_outcome" in f for f in fs):
            base = [str(f.get("baseline_outcome") or "not judged") for f in fs]
            s["baseline"] = {name: base.count(name) for name in (*COUNTED, "not judged")}
        ttr = [f.get("link_time_to_reconnect_s" if str(kind).startswith("link_") else "time_to_reconnect_s")
               for f, o in zip(fs, outcome) if o == "split and recovered"]
        s["time_to_reconnect_s"] = mean_ci95(ttr)
        s["delta_v_in_window_mps"] = mean_ci95([f.get("delta_v_in_window_mps") for f in fs])
        out[kind] = s
    return out


def _fault_lines(rows: list[dict[str, Any]], meta: dict[str, Any], f: Callable[[Any], str]) -> list[str]:
    """The fault campaign's part of report.md: outcomes per kind, and the extra ΔV over the baseline."""
    stats = fault_stats(rows)
    holds = sorted({float(x["hold_s"]) for r in rows if r.get("status") == "ok"
                    for x in json.loads(r.get("faults") or "[]") if x.get("hold_s") is not None})
    held = " or ".join(f"{f(h)} s" for h in holds) or "the run's [recovery].hold_s"
    lines = [f"## Faults (drawn from {meta['faults']['file']})", "",
             "Each fault judged on a graph of the swarm: a link fault on the link graph of its deliveries, any other on "
             "the camera-visibility graph. Never split: one weakly connected component all through the window and "
             f"after it. Split and recovered: one component again after the window, staying so for {held}. Not "
             "recovered: split and not whole again for that long by the run's end. Not judged: no such graph, the "
             "fault had not ended, or the swarm was whole at the run's end but not for that long. Fractions of the "
             "judged faults, each with Wilson's 95 % interval; with --baseline, a second row per kind judges the same "
             "windows on the same seeds' runs without faults (what the swarm does anyway).", "",
             "| fault kind | drawn | judged | never split | split and recovered | not recovered | "
             "time to reconnect, mean [s] | swarm ΔV in window, mean [m/s] |", "|---|---:|---:|---|---|---|---:|---:|"]
    for kind, s in stats.items():
        cells = []
        for name in COUNTED:
            c = s[name]
            ci = "" if c["ci95_low"] is None else f" [{c['ci95_low']:.3f}, {c['ci95_high']:.3f}]"
            cells.append(f"{c['n']} ({f(c['fraction'])}{ci})")
        lines.append(f"| {kind} | {s['drawn']} | {s['judged']} | {' | '.join(cells)} | "
                     f"{f(s['time_to_reconnect_s']['mean'])} | {f(s['delta_v_in_window_mps']['mean'])} |")
        if "baseline" in s:
            b = s["baseline"]
            lines.append(f"| {kind}, same windows without faults | {s['drawn']} | {s['drawn'] - b['not judged']} | "
                         f"{' | '.join(str(b[name]) for name in COUNTED)} | | |")
    extra = mean_ci95([r.get("delta_v_extra_mps") for r in rows if r.get("status") == "ok"])
    if extra["n"]:
        ci = "" if extra["ci95_low"] is None else f", 95 % CI [{f(extra['ci95_low'])}, {f(extra['ci95_high'])}]"
        lines += ["", f"Extra ΔV over the same seed without faults (OUT/baseline): mean {f(extra['mean'])} m/s{ci} "
                      f"over {extra['n']} runs."]
    return [*lines, ""]


def _md_html(lines: list[str]) -> str:
    """The few markdown forms of a report part (a `##` heading, paragraphs, one pipe table) as HTML."""
    import html

    out, table = [], []
    for line in [*lines, ""]:
        if line.startswith("|"):
            if not set(line) <= set("|-: "):
                table.append("<tr>" + "".join(f"<td>{html.escape(c.strip())}</td>" for c in line.strip("|").split("|"))
                             + "</tr>")
            continue
        if table:
            out.append("<table>" + "".join(table) + "</table>")
            table = []
        if line.startswith("## "):
            out.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line:
            out.append(f"<p>{html.escape(line)}</p>")
    return "".join(out)


def write_report(out: Path, rows: list[dict[str, Any]], meta: dict[str, Any]) -> tuple[Path, Path]:
    """OUT/report.md and OUT/report.html: runs ok / failed, mean and 95 % CI of dV and the metrics."""
    ok = [r for r in rows if r.get("status") == "ok"]
    bad = [r for r in rows if r.get("status") != "ok"]
    stats = {}
    for col, label in REPORT_METRICS:
        if any(col in r for r in ok):
            stats[col] = (label, mean_ci95([r.get(col) for r in ok]))
    f = lambda v: "" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v))  # noqa: E731
    ci = lambda s: "" if s["ci95_low"] is None else f"[{f(s['ci95_low'])}, {f(s['ci95_high'])}]"  # noqa: E731
    head = ["| metric | n | mean | 95 % CI of the mean | std | min | max |", "|---|---:|---:|---|---:|---:|---:|"]
    lines = [f"| {label} | {s['n']} | {f(s['mean'])} | "
             f"{ci(s)} | "
             f"{f(s['std'])} | {f(s['min'])} | {f(s['max'])} |" for label, s in stats.values()]
    durations = sorted({r["duration_s"] for r in ok if isinstance(r.get("duration_s"), (int, float))})
    duration = (f(float(meta["duration_s"])) if meta.get("duration_s") is not None
                else (f(durations[0]) if len(durations) == 1 else ", ".join(map(f, durations)) or "the scenario's"))
    md = [f"# Campaign: {meta.get('scenario')}", "",
          f"{len(rows)} runs ({len(ok)} ok, {len(bad)} failed); seeds {meta.get('seeds_text')}; "
          f"duration {duration} s; --set {list(meta.get('sets') or []) or 'none'}; "
          f"executor {meta.get('executor')}; campaign wall {f(meta.get('wall_s'))} s.", "",
          *head, *lines, ""]
    if meta.get("faults"):
        md += _fault_lines(rows, meta, f)
    if bad:
        md += ["## Failed runs", "", "| seed | error |", "|---:|---|",
               *[f"| {r['seed']} | {str(r.get('error')).replace('|', '/')} |" for r in bad], ""]
    md += ["Table: `campaign.parquet` / `campaign.csv` (one row per run; every scalar of the run's summary.json, "
           "metrics under `metrics.*`). The confidence interval is Student's t on the mean over seeds.", ""]
    (Path(out) / "report.md").write_text("\n".join(md))
    import html

    rows_html = "".join(
        f"<tr><td>{html.escape(label)}</td><td>{s['n']}</td><td>{f(s['mean'])}</td><td>"
        f"{ci(s)}</td><td>{f(s['std'])}</td>"
        f"<td>{f(s['min'])}</td><td>{f(s['max'])}</td></tr>" for label, s in stats.values())
    bad_html = "".join(f"<tr><td>{r['seed']}</td><td>{html.escape(str(r.get('error')))}</td></tr>" for r in bad)
    page = (f"<!doctype html><meta charset=utf-8><title>campaign {html.escape(str(meta.get('scenario')))}</title>"
            f"<style>body{{font-family:sans-serif}}td,th{{padding:2px 8px;text-align:right}}</style>"
            f"<h1>Campaign: {html.escape(str(meta.get('scenario')))}</h1><p>{len(rows)} runs ({len(ok)} ok, {len(bad)} failed), "
            f"seeds {html.escape(str(meta.get('seeds_text')))}, duration {html.escape(str(duration))} s.</p>"
            f"<table><tr><th>metric</th><th>n</th><th>mean</th><th>95 % CI</th><th>std</th><th>min</th><th>max</th></tr>"
            f"{rows_html}</table>" + (_md_html(_fault_lines(rows, meta, f)) if meta.get("faults") else "") +
            (f"<h2>Failed runs</h2><table>{bad_html}</table>" if bad else "") +
            "<p>Table: campaign.parquet / campaign.csv.</p>")
    (Path(out) / "report.html").write_text(page)
    return Path(out) / "report.md", Path(out) / "report.html"


def _file_sha256(path: str) -> str | None:
    """sha256 of a file's bytes (None when it cannot be read: the run itself then reports the file)."""
    import hashlib

    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def run_campaign(scenario: str, seeds: Sequence[int], out: Path, *, sets: Sequence[str] = (),
                 duration_s: float | None = None, executor: str = "local", jobs: int = 2, scheduler: str | None = None,
                 metrics: bool = True, keep_recording: bool = True, retry_failed: bool = False,
                 on_row: Callable[[dict[str, Any]], None] | None = None, record: str = "truth",
                 faults: str | Path | None = None, baseline: bool = False) -> dict[str, Any]:
    """Run the seeds not finished yet in OUT, then write the table and the report of all of them.
    `faults`: a faults file (deploy/fault_draws.py), each run flies the faults drawn for its seed;
    with `baseline`, the same seeds without faults are run first into OUT/baseline (a campaign of
    its own) and the report gives each run's extra ΔV over its baseline.
    Returns {"ran": [seeds run now], "skipped": [seeds already finished], "rows", "table", "report"}."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scenario = str(Path(scenario).resolve())
    meta_path = out / "campaign.json"
    meta: dict[str, Any] = {"scenario": scenario, "sets": list(sets), "duration_s": duration_s, "metrics": metrics,
                            "scenario_sha256": _file_sha256(scenario)}
    base_rows: list[dict[str, Any]] | None = None
    if faults is not None:
        faults = str(Path(faults).resolve())
        meta["faults"] = {"file": faults, "sha256": _file_sha256(faults)}
        if baseline:
            base_rows = run_campaign(scenario, seeds, out / "baseline", sets=sets, duration_s=duration_s,
                                     executor=executor, jobs=jobs, scheduler=scheduler, metrics=metrics,
                                     keep_recording=keep_recording, retry_failed=retry_failed, on_row=on_row,
                                     record=record)["rows"]
    if meta_path.is_file():  # resuming: it must be the same campaign
        try:
            old = json.loads(meta_path.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f"{meta_path}: not a campaign's record ({' '.join(str(exc).split())[:100]}); "
                             f"use another --out") from None
        for k in ("scenario", "sets", "duration_s", "faults", "scenario_sha256"):  # (an edited scenario file is another campaign)
            if old.get(k) != meta.get(k):
                raise ValueError(f"{out} holds a campaign with {k} = {old.get(k)!r}, not {meta.get(k)!r}; "
                                 f"use another --out")
    done = finished_seeds(out, retry_failed)
    todo = [int(s) for s in seeds if int(s) not in done]
    skipped = [int(s) for s in seeds if int(s) in done]
    meta.update({"executor": executor, "seeds": [int(s) for s in seeds], "record": record})
    _write_atomic(meta_path, json.dumps(meta, indent=1))
    t0 = time.monotonic()
    calls = {s: (scenario, tuple(sets), s, str(out), duration_s, metrics, keep_recording, record, faults)
             for s in todo}

    def got(_seed: int, row: dict[str, Any]) -> None:
        if not row_path(out, row["seed"]).is_file():  # the worker could not write it (died, other filesystem)
            _write_atomic(row_path(out, row["seed"]), json.dumps(row, default=_json_default))
        if on_row:
            on_row(row)

    execute(run_seed, calls, executor=executor, jobs=jobs, scheduler=scheduler, on_row=got)
    wall = time.monotonic() - t0
    rows = load_rows(out, seeds)
    meta.update({"wall_s": wall, "seeds_text": _seeds_text([int(s) for s in seeds])})
    if base_rows is not None:
        base = {r["seed"]: r for r in base_rows if r.get("status") == "ok"}
        for r in rows:
            b = base.get(r["seed"])
            if r.get("status") == "ok" and b is not None:
                r["delta_v_extra_mps"] = r["delta_v_total_mps"] - b["delta_v_total_mps"]
                if r.get("faults"):
                    from swarmhil.dashboards.sections.faults import with_baseline_outcomes  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

                    r["faults"] = json.dumps(with_baseline_outcomes(json.loads(r["faults"]),
                                                                    run_dir(out / "baseline", int(r["seed"]))))
    table = write_table(out, rows)
    report = write_report(out, rows, meta)
    return {"ran": todo, "skipped": skipped, "rows": rows, "table": table, "report": report, "wall_s": wall}


def _seeds_text(seeds: list[int]) -> str:
    if seeds and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}..{seeds[-1]}"
    return ",".join(map(str, seeds))
