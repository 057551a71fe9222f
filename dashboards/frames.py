"""A run as data frames (issue 18): what `swarmhil.load(RUN)` returns and what the report writes to
RUN/report/data/ as Parquet and CSV. Reading only: no figures, no HTML.

Everything comes from RUN/run.mcap through the public contract (the `mcap` reader and the
`mcap-protobuf-support` decoder, from the schemas embedded in the file), plus RUN/summary.json
where present. One row per:

- `truth`: (step, body). Columns step, t_s, id, kind, alive, x_m y_m z_m (LVLH position), vx_mps
  vy_mps vz_mps, ax_cmd_mps2 ay_cmd_mps2 az_cmd_mps2 (the command as recorded: applied over the
  step that ENDED at t_k in the current contract, bus/swarmhil.proto), delta_v_mps (cumulative),
  roe_da_m ... roe_diy_m (a*(da, dl, dex, dey, dix, diy); NaN where not recorded), qw qx qy qz
  (attitude, NaN where not flown), u_rad, semi_major_axis_m, mean_motion_radps. The values are
  the recorded doubles, unchanged: `truth` round-trips the Truth messages exactly (first message of
  each step, as dashboards/truth_io.read_truth).
- `commands`: (step, spacecraft) of every `sc/<id>/act` ActuatorCommand: ax_mps2 ay_mps2 az_mps2
  (held over the step that starts at t_k), torque, controller, isl_tx_count.
- `link`: (LinkStats sample, src, dst, type) of the channel's cumulative counters (`link/stats`);
  dst "*" is the transmitter's own row. `link_totals`: one row per LinkStats sample.
- `events`: every `event` (t_s, step, source, kind, subject, detail).
- `metrics_series`: per step, the swarm metrics of dashboards/metrics.py (components, largest
  component, components of the orbit union, total dV, edges of the visibility digraph).
- `metrics`: the scalar metrics of summary.json["metrics"] flattened to (metric, value) rows.

pandas, not polars: pyarrow (already a dependency) is its Parquet engine, matplotlib/Plotly and
notebooks take its frames directly, and the tables are small enough (a 24 h, 20-spacecraft run:
173 k truth rows) that polars' speed buys nothing here (docs/analysis.md).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.bus.keys import split_topic
from swarmhil.bus.mcap_tools import run_of_recording
from swarmhil.dashboards.metrics import compute_metrics
from swarmhil.dashboards.run_config import camera_from_config, run_config
from swarmhil.dashboards.truth_io import read_truth

TRUTH, COMMAND, LINK_STATS, EVENT = ("swarmhil.v1.Truth", "swarmhil.v1.ActuatorCommand", "swarmhil.v1.LinkStats",
                                     "swarmhil.v1.Event")
ROE_COLUMNS = ["roe_da_m", "roe_dl_m", "roe_dex_m", "roe_dey_m", "roe_dix_m", "roe_diy_m"]
COUNTERS = ["messages", "payload_bytes", "wire_bytes", "dropped_range", "dropped_occulted", "dropped_lost",
            "dropped_queue"]
TABLES = ("truth", "commands", "link", "link_totals", "events", "metrics_series", "metrics")


@dataclass
class RunData:
    """One run as pandas data frames (module docstring for the columns)."""

    run_dir: Path
    run: str
    config: dict[str, Any]
    summary: dict[str, Any]
    truth: Any
    commands: Any
    link: Any
    link_totals: Any
    events: Any
    metrics_series: Any = None
    metrics: Any = None
    extra: dict[str, Any] = field(default_factory=dict)

    def tables(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in TABLES if getattr(self, name) is not None}


def _rel(topic: str) -> str:
    return split_topic(topic)[1]


def read_frames(mcap_path: str | Path) -> dict[str, Any]:
    """truth, commands, link, link_totals and events of a recording as data frames, in one pass."""
    import pandas as pd
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    truth: dict[str, list] = {k: [] for k in ["step", "t_s", "id", "kind", "alive", "x_m", "y_m", "z_m", "vx_mps",
                                              "vy_mps", "vz_mps", "ax_cmd_mps2", "ay_cmd_mps2", "az_cmd_mps2",
                                              "delta_v_mps", *ROE_COLUMNS, "qw", "qx", "qy", "qz", "u_rad",
                                              "semi_major_axis_m", "mean_motion_radps"]}
    cmd: dict[str, list] = {k: [] for k in ["step", "t_s", "id", "controller", "ax_mps2", "ay_mps2", "az_mps2",
                                            "torque_x_nm", "torque_y_nm", "torque_z_nm", "isl_tx_count"]}
    link: dict[str, list] = {k: [] for k in ["step", "t_s", "src", "dst", "type", *COUNTERS]}
    tot: dict[str, list] = {k: [] for k in ["step", "t_s", "tx_messages", "rx_messages", "rejected_packets"]}
    ev: dict[str, list] = {k: [] for k in ["step", "t_s", "source", "kind", "subject", "detail"]}
    seen: set[int] = set()
    nan4 = (math.nan,) * 4
    with open(mcap_path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        run = run_of_recording(reader) or ""
        s = reader.get_summary()
        topics = sorted({ch.topic for ch in s.channels.values()}) if s is not None else []
        wanted = [t for t in topics if _rel(t) in ("truth", "link/stats", "event")
                  or (_rel(t).startswith("sc/") and _rel(t).endswith("/act"))]
        for schema, ch, _m, msg in reader.iter_decoded_messages(topics=wanted):
            name = schema.name if schema is not None else ""
            if name == TRUTH:
                k = int(msg.header.step)
                if k in seen:
                    continue
                seen.add(k)
                for b in msg.bodies:
                    truth["step"].append(k)
                    truth["t_s"].append(msg.header.t)
                    truth["id"].append(b.id)
                    truth["kind"].append(b.kind or "spacecraft")
                    truth["alive"].append(b.alive)
                    for col, v in zip(("x_m", "y_m", "z_m"), (b.position_m.x, b.position_m.y, b.position_m.z)):
                        truth[col].append(v)
                    for col, v in zip(("vx_mps", "vy_mps", "vz_mps"),
                                      (b.velocity_mps.x, b.velocity_mps.y, b.velocity_mps.z)):
                        truth[col].append(v)
                    for col, v in zip(("ax_cmd_mps2", "ay_cmd_mps2", "az_cmd_mps2"),
                                      (b.accel_cmd_mps2.x, b.accel_cmd_mps2.y, b.accel_cmd_mps2.z)):
                        truth[col].append(v)
                    truth["delta_v_mps"].append(b.delta_v_mps)
                    roe = list(b.roe_m) if len(b.roe_m) == 6 else [math.nan] * 6
                    for col, v in zip(ROE_COLUMNS, roe):
                        truth[col].append(v)
                    q = (b.attitude.w, b.attitude.x, b.attitude.y, b.attitude.z) if b.HasField("attitude") else nan4
                    for col, v in zip(("qw", "qx", "qy", "qz"), q):
                        truth[col].append(v)
                    truth["u_rad"].append(msg.u_rad)
                    truth["semi_major_axis_m"].append(msg.semi_major_axis_m)
                    truth["mean_motion_radps"].append(msg.mean_motion_radps)
            elif name == COMMAND:
                cmd["step"].append(int(msg.header.step))
                cmd["t_s"].append(msg.header.t)
                cmd["id"].append(_rel(ch.topic).split("/")[1])
                cmd["controller"].append(msg.controller)
                for col, v in zip(("ax_mps2", "ay_mps2", "az_mps2", "torque_x_nm", "torque_y_nm", "torque_z_nm"),
                                  (msg.accel_mps2.x, msg.accel_mps2.y, msg.accel_mps2.z,
                                   msg.torque_nm.x, msg.torque_nm.y, msg.torque_nm.z)):
                    cmd[col].append(v)
                cmd["isl_tx_count"].append(int(msg.isl_tx_count))
            elif name == LINK_STATS:
                k, t = int(msg.header.step), msg.header.t
                for c in msg.links:
                    link["step"].append(k)
                    link["t_s"].append(t)
                    link["src"].append(c.src)
                    link["dst"].append(c.dst)
                    link["type"].append(c.type)
                    for col in COUNTERS:
                        link[col].append(int(getattr(c, col)))
                tot["step"].append(k)
                tot["t_s"].append(t)
                for col in ("tx_messages", "rx_messages", "rejected_packets"):
                    tot[col].append(int(getattr(msg, col)))
            elif name == EVENT:
                ev["step"].append(int(msg.header.step))
                ev["t_s"].append(msg.header.t)
                ev["source"].append(msg.header.source)
                ev["kind"].append(msg.kind)
                ev["subject"].append(msg.subject)
                ev["detail"].append(msg.detail)

    def frame(cols: dict[str, list], ints: tuple[str, ...] = ("step",)) -> Any:
        df = pd.DataFrame(cols)
        for c in ints:
            if c in df:
                df[c] = df[c].astype("int64")
        return df

    out = {"run": run,
           "truth": frame(truth).sort_values(["step"], kind="stable").reset_index(drop=True),
           "commands": frame(cmd, ("step", "isl_tx_count")).sort_values(["step", "id"], kind="stable").reset_index(drop=True),
           "link": frame(link, ("step", *COUNTERS)),
           "link_totals": frame(tot, ("step", "tx_messages", "rx_messages", "rejected_packets")),
           "events": frame(ev)}
    return out


def metrics_series_frame(m: Any) -> Any:
    """Per-step series of dashboards.metrics.SwarmMetrics."""
    import pandas as pd

    return pd.DataFrame({"t_s": m.t_s, "n_components": m.n_components.astype("int64"),
                         "largest_component": m.largest.astype("int64"),
                         "n_components_orbit_union": m.n_components_orbit.astype("int64"),
                         "visibility_edges": m.vis.sum(axis=(1, 2)).astype("int64"),
                         "delta_v_total_mps": m.delta_v_mps.sum(axis=1),
                         "accel_max_mps2": np.nanmax(m.accel_mps2, axis=1) if m.accel_mps2.size else 0.0})


def flatten(d: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """Nested dict to (dotted key, scalar) rows; lists become JSON text."""
    out: list[tuple[str, Any]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out += flatten(v, key + ".")
        elif isinstance(v, (list, tuple)):
            out.append((key, json.dumps(v)))
        else:
            out.append((key, v))
    return out


def metrics_frame(metrics: dict[str, Any]) -> Any:
    """summary.json["metrics"] as (metric, value, text) rows: numbers in value, everything else in text."""
    import pandas as pd

    rows = flatten(metrics)
    num = [float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else
           (float(v) if isinstance(v, bool) else math.nan) for _k, v in rows]
    txt = [None if isinstance(v, (int, float)) else (None if v is None else str(v)) for _k, v in rows]
    return pd.DataFrame({"metric": [k for k, _v in rows], "value": num, "text": txt})


def write_tables(tables: dict[str, Any], out_dir: Path) -> list[dict[str, Any]]:
    """Each frame as out_dir/<name>.parquet and .csv; returns (name, rows, columns) records."""
    out_dir.mkdir(parents=True, exist_ok=True)
    done = []
    for name, df in tables.items():
        df.to_parquet(out_dir / f"{name}.parquet", index=False)
        df.to_csv(out_dir / f"{name}.csv", index=False)
        done.append({"name": name, "rows": int(len(df)), "columns": list(map(str, df.columns))})
    return done


def load(run_dir: str | Path, metrics: bool = True) -> RunData:
    """The run in run_dir as data frames (module docstring). With `metrics`, the swarm metrics too:
    from RUN/report/data/ when a report wrote them, else computed here from the truth."""
    import pandas as pd

    d = Path(run_dir)
    mcap = d / "run.mcap"
    if not mcap.is_file():
        raise ValueError(f"{d}: no run.mcap (not a run directory)")
    spath = d / "summary.json"
    summary = json.loads(spath.read_text()) if spath.is_file() else {}
    fr = read_frames(mcap)
    data = RunData(run_dir=d, run=fr["run"] or str(summary.get("run", "")), config=run_config(d) or {},
                   summary=summary, truth=fr["truth"], commands=fr["commands"], link=fr["link"],
                   link_totals=fr["link_totals"], events=fr["events"])
    if metrics:
        tables = d / "report" / "data"
        if (tables / "metrics_series.parquet").is_file() and (tables / "metrics.parquet").is_file():
            data.metrics_series = pd.read_parquet(tables / "metrics_series.parquet")
            data.metrics = pd.read_parquet(tables / "metrics.parquet")
        else:
            m = compute_metrics(read_truth(mcap, data.run or None), camera_from_config(data.config))
            data.metrics_series = metrics_series_frame(m)
            data.metrics = metrics_frame(summary.get("metrics") or m.summary)
    return data
