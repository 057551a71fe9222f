"""Scenario files (deploy/scenarios/*.toml): schema, validation and initial conditions.

Every error names the file and the bad field, e.g.
`drift-20.toml: [orbit].semi_major_axis_m must be a number > 6378137 (got -1)`.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bus.keys import check_token

SECTIONS = {
    "run", "orbit", "plant", "camera", "actuator", "controller", "sensing", "dispersion",
    "spacecraft", "link", "beacon", "nav", "time", "viz",
}


class ScenarioError(ValueError):
    pass


@dataclass(frozen=True)
class OrbitCfg:
    semi_major_axis_m: float
    inclination_rad: float
    raan_rad: float
    u0_rad: float

    @property
    def mean_motion_radps(self) -> float:
        return math.sqrt(3.986004418e14 / self.semi_major_axis_m**3)


@dataclass
class Scenario:
    name: str
    source: str
    duration_s: float
    step_s: float
    seed: int
    mode: str
    speed: float
    orbit: OrbitCfg
    fidelity: str
    drag: dict[str, Any] | None
    camera: dict[str, float]
    max_accel_mps2: float
    controller: str
    controller_params: dict[str, Any]
    sensing: dict[str, Any]
    ids: list[str]
    roe_m: np.ndarray  # (N, 6)
    lockstep_timeout_s: float
    dead_after_missed: int
    decision_period_steps: int = 1
    sections: dict[str, Any] = field(default_factory=dict)  # raw tables for link, beacon, nav, viz

    @property
    def steps(self) -> int:
        return int(round(self.duration_s / self.step_s))

    def with_overrides(self, *, duration_s: float | None = None, seed: int | None = None,
                       mode: str | None = None, speed: float | None = None) -> "Scenario":
        import copy

        s = copy.copy(self)
        if duration_s is not None:
            s.duration_s = _positive(self.source, "--duration", duration_s)
        if mode is not None:
            s.mode = _choice(self.source, "--mode", mode, ("lockstep", "realtime"))
        if speed is not None:
            s.speed = _positive(self.source, "--speed", speed)
        if seed is not None and seed != self.seed:
            s.seed = int(seed)
            if self.sections.get("_generated"):
                s.ids, s.roe_m = _generate(self.source, self.sections["dispersion"], s.seed, self)
        return s


def _err(src: str, where: str, msg: str, got: Any) -> ScenarioError:
    return ScenarioError(f"{src}: {where} {msg} (got {got!r})")


def _num(src: str, where: str, value: Any, lo: float | None = None, hi: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _err(src, where, "must be a finite number", value)
    if lo is not None and value < lo:
        raise _err(src, where, f"must be >= {lo}", value)
    if hi is not None and value > hi:
        raise _err(src, where, f"must be <= {hi}", value)
    return float(value)


def _positive(src: str, where: str, value: Any) -> float:
    v = _num(src, where, value)
    if v <= 0:
        raise _err(src, where, "must be > 0", value)
    return v


def _choice(src: str, where: str, value: Any, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise _err(src, where, f"must be one of {list(choices)}", value)
    return str(value)


def _table(src: str, doc: dict[str, Any], name: str, allowed: set[str] | None) -> dict[str, Any]:
    t = doc.get(name, {})
    if not isinstance(t, dict):
        raise _err(src, f"[{name}]", "must be a table", t)
    if allowed is not None:
        unknown = sorted(set(t) - allowed)
        if unknown:
            raise _err(src, f"[{name}].{unknown[0]}", f"is not a known field; known: {sorted(allowed)}", t[unknown[0]])
    return t


def _vec3(src: str, where: str, value: Any) -> list[float]:
    if not isinstance(value, list) or len(value) != 3:
        raise _err(src, where, "must be a list of three numbers", value)
    return [_num(src, f"{where}[{i}]", v) for i, v in enumerate(value)]


def _roe6(src: str, where: str, value: Any) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 6:
        raise _err(src, where, "must be a list of six numbers (metres: a*da, a*dl, a*dex, a*dey, a*dix, a*diy)", value)
    return np.array([_num(src, f"{where}[{i}]", v) for i, v in enumerate(value)])


def load_scenario(path: str | Path) -> Scenario:
    p = Path(path)
    src = p.name
    try:
        text = p.read_text()
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read scenario ({exc.strerror})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{src}: not valid TOML: {exc}") from None
    return parse_scenario(doc, src)


def parse_scenario(doc: dict[str, Any], src: str = "<scenario>") -> Scenario:
    unknown = sorted(set(doc) - SECTIONS)
    if unknown:
        raise _err(src, f"[{unknown[0]}]", f"is not a known section; known: {sorted(SECTIONS)}", "…")
    run = _table(src, doc, "run", {"name", "duration_s", "step_s", "seed", "mode", "speed", "description"})
    name = check_name(src, run.get("name", Path(src).stem))
    duration = _positive(src, "[run].duration_s", run.get("duration_s", 600.0))
    step = _positive(src, "[run].step_s", run.get("step_s", 10.0))
    if duration < step:
        raise _err(src, "[run].duration_s", f"must be at least one step ({step} s)", duration)
    seed = run.get("seed", 1)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise _err(src, "[run].seed", "must be a non-negative integer", seed)
    mode = _choice(src, "[run].mode", run.get("mode", "lockstep"), ("lockstep", "realtime"))
    speed = _positive(src, "[run].speed", run.get("speed", 1.0))

    o = _table(src, doc, "orbit", {"semi_major_axis_m", "inclination_deg", "raan_deg", "u0_deg"})
    orbit = OrbitCfg(
        semi_major_axis_m=_num(src, "[orbit].semi_major_axis_m", o.get("semi_major_axis_m", 6878137.0), lo=6378137.0 + 100e3),
        inclination_rad=math.radians(_num(src, "[orbit].inclination_deg", o.get("inclination_deg", 97.4), 0, 180)),
        raan_rad=math.radians(_num(src, "[orbit].raan_deg", o.get("raan_deg", 0.0))),
        u0_rad=math.radians(_num(src, "[orbit].u0_deg", o.get("u0_deg", 0.0))),
    )
    pl = _table(src, doc, "plant", {"fidelity", "drag"})
    fidelity = _choice(src, "[plant].fidelity", pl.get("fidelity", "linear"), ("linear", "j2"))
    drag = pl.get("drag")
    if drag is not None and not isinstance(drag, dict):
        raise _err(src, "[plant].drag", "must be a table (ballistic_coefficient_m2pkg, ...) or absent", drag)
    cam = _table(src, doc, "camera", {"detection_range_m", "image_px", "focal_px", "frame_period_s"})
    camera = {
        "detection_range_m": _positive(src, "[camera].detection_range_m", cam.get("detection_range_m", 500.0)),
        "image_px": int(_positive(src, "[camera].image_px", cam.get("image_px", 1080))),
        "focal_px": _positive(src, "[camera].focal_px", cam.get("focal_px", 1000.0)),
    }
    act = _table(src, doc, "actuator", {"max_accel_mps2"})
    max_accel = _positive(src, "[actuator].max_accel_mps2", act.get("max_accel_mps2", 1e-3))
    ctl = _table(src, doc, "controller", {"name", "params", "decision_period_s"})
    from agent.controller import known_controllers

    controller = _choice(src, "[controller].name", ctl.get("name", "null"), tuple(known_controllers()))
    params = ctl.get("params", {})
    if not isinstance(params, dict):
        raise _err(src, "[controller].params", "must be a table", params)
    params = {"max_accel_mps2": max_accel, **params}
    decision_period = _positive(src, "[controller].decision_period_s", ctl.get("decision_period_s", step))
    decision_steps = int(round(decision_period / step))
    if decision_steps < 1 or abs(decision_steps * step - decision_period) > 1e-9 * decision_period:
        raise _err(src, "[controller].decision_period_s", f"must be a whole number of steps of {step} s", decision_period)
    sens = _table(src, doc, "sensing", {"kind", "roe_noise_fraction", "pointing_error_rad", "pointing_jitter_rad"})
    sensing = {
        "kind": _choice(src, "[sensing].kind", sens.get("kind", "rel"), ("rel", "scene")),
        "roe_noise_fraction": _num(src, "[sensing].roe_noise_fraction", sens.get("roe_noise_fraction", 0.0), 0.0, 10.0),
        "pointing_error_rad": _vec3(src, "[sensing].pointing_error_rad", sens.get("pointing_error_rad", [0.0, 0.0, 0.0])),
        "pointing_jitter_rad": _num(src, "[sensing].pointing_jitter_rad", sens.get("pointing_jitter_rad", 0.0), 0.0, 0.1),
    }
    if sensing["kind"] == "scene":
        from agent.perception import nav_config

        try:
            nav_config(doc.get("nav"))
        except ValueError as exc:
            raise ScenarioError(f"{src}: {exc}") from None
    tm = _table(src, doc, "time", {"lockstep_timeout_s", "dead_after_missed"})
    timeout = _positive(src, "[time].lockstep_timeout_s", tm.get("lockstep_timeout_s", 5.0))
    dead_after = int(_positive(src, "[time].dead_after_missed", tm.get("dead_after_missed", 3)))

    sc = Scenario(
        name=name, source=src, duration_s=duration, step_s=step, seed=seed, mode=mode, speed=speed,
        orbit=orbit, fidelity=fidelity, drag=drag, camera=camera, max_accel_mps2=max_accel,
        controller=controller, controller_params=params, sensing=sensing, ids=[], roe_m=np.zeros((0, 6)),
        lockstep_timeout_s=timeout, dead_after_missed=dead_after, decision_period_steps=decision_steps,
        sections={k: doc[k] for k in ("link", "beacon", "nav", "viz", "dispersion") if k in doc},
    )
    if "link" in doc:
        from bus.channel import LinkConfigError, parse_link_config

        try:
            parse_link_config(doc["link"], src, seed)
        except LinkConfigError as exc:
            raise ScenarioError(str(exc)) from None
    if "spacecraft" in doc:
        sc.ids, sc.roe_m = _explicit(src, doc["spacecraft"])
    elif "dispersion" in doc:
        sc.sections["_generated"] = True
        sc.ids, sc.roe_m = _generate(src, doc["dispersion"], seed, sc)
    else:
        raise ScenarioError(f"{src}: no spacecraft: give [[spacecraft]] tables (id, roe_m) or a [dispersion] table")
    return sc


def check_name(src: str, name: Any) -> str:
    try:
        return check_token(name, "run name")
    except ValueError as exc:
        raise _err(src, "[run].name", str(exc), name) from None


def _explicit(src: str, items: Any) -> tuple[list[str], np.ndarray]:
    if not isinstance(items, list) or not items:
        raise _err(src, "[[spacecraft]]", "must be a non-empty array of tables", items)
    ids: list[str] = []
    roes = []
    for i, item in enumerate(items):
        where = f"[[spacecraft]][{i}]"
        if not isinstance(item, dict):
            raise _err(src, where, "must be a table", item)
        unknown = sorted(set(item) - {"id", "roe_m"})
        if unknown:
            raise _err(src, f"{where}.{unknown[0]}", "is not a known field; known: ['id', 'roe_m']", item[unknown[0]])
        if "id" not in item:
            raise _err(src, f"{where}.id", "is required", None)
        try:
            sid = check_token(item["id"], "spacecraft id")
        except ValueError as exc:
            raise _err(src, f"{where}.id", str(exc), item["id"]) from None
        if sid in ids:
            raise _err(src, f"{where}.id", "is a duplicate", sid)
        if sid.startswith(("plant", "recorder", "channel", "viz")):
            raise _err(src, f"{where}.id", "must not start with a process name (plant, recorder, channel, viz)", sid)
        ids.append(sid)
        roes.append(_roe6(src, f"{where}.roe_m", item.get("roe_m")))
    return ids, np.array(roes)


def _generate(src: str, d: Any, seed: int, sc: Scenario) -> tuple[list[str], np.ndarray]:
    from plant.dispersion import Dispersion, draw_roe
    from plant.dynamics.roe_linear import roe_to_lvlh
    from plant.sensors import CameraGeometry, visibility_matrix, weakly_connected

    if not isinstance(d, dict):
        raise _err(src, "[dispersion]", "must be a table", d)
    allowed = {"count", "sigma_roe_m", "along_track_spacing_m", "mean_roe_m", "require_weakly_connected", "id_prefix", "max_tries"}
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise _err(src, f"[dispersion].{unknown[0]}", f"is not a known field; known: {sorted(allowed)}", d[unknown[0]])
    count = d.get("count")
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= 1000:
        raise _err(src, "[dispersion].count", "must be an integer in 1..1000", count)
    disp = Dispersion(
        count=count,
        sigma_roe_m=tuple(_roe6(src, "[dispersion].sigma_roe_m", d.get("sigma_roe_m"))),  # type: ignore[arg-type]
        along_track_spacing_m=_num(src, "[dispersion].along_track_spacing_m", d.get("along_track_spacing_m", 0.0), 0.0),
        mean_roe_m=tuple(_roe6(src, "[dispersion].mean_roe_m", d.get("mean_roe_m", [0.0] * 6))),  # type: ignore[arg-type]
    )
    prefix = d.get("id_prefix", "sc")
    width = max(2, len(str(count)))
    ids = [check_token(f"{prefix}{i + 1:0{width}d}") for i in range(count)]
    rng = np.random.default_rng(seed)
    want_connected = bool(d.get("require_weakly_connected", False))
    tries = int(d.get("max_tries", 2000))
    cam = CameraGeometry(sc.camera["detection_range_m"], sc.camera["image_px"], sc.camera["focal_px"])
    for _ in range(tries):
        roe = draw_roe(rng, disp)
        if not want_connected:
            return ids, roe
        pos, _v = roe_to_lvlh(roe, sc.orbit.u0_rad, sc.orbit.mean_motion_radps)
        if weakly_connected(visibility_matrix(pos, cam)):
            return ids, roe
    raise _err(src, "[dispersion]", f"gave no weakly connected initial swarm in {tries} draws; widen or tighten it", d)
