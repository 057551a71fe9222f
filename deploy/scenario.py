"""Scenario files (deploy/scenarios/*.toml): schema, validation and initial conditions.

Every error names the file and the bad field, e.g.
`drift-20.toml: [orbit].semi_major_axis_m must be a number > 6378137 (got -1)`.
"""
from __future__ import annotations

import logging

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarmhil.bus.discovery import RoomError, add_rooms
from swarmhil.bus.keys import check_token

SECTIONS = {
    "run", "orbit", "plant", "camera", "actuator", "controller", "sensing", "dispersion",
    "spacecraft", "body", "link", "beacon", "nav", "time", "viz", "supervision", "security", "fault",
    "contact", "recovery",
}
RESTART_POLICIES = ("never", "on-failure")
PROPAGATORS = ("linear", "j2", "cw", "inertial")  # plant/dynamics/propagator.py


class ScenarioError(ValueError):
    pass


@dataclass(frozen=True)
class OrbitCfg:
    semi_major_axis_m: float
    inclination_rad: float
    raan_rad: float
    u0_rad: float          # argument of latitude at t = 0 (argp + true anomaly)
    eccentricity: float = 0.0   # [plant] fidelity = "inertial" only
    argp_rad: float = 0.0       # argument of periapsis (with eccentricity > 0)

    @property
    def mean_motion_radps(self) -> float:
        from swarmhil.plant.dynamics.constants import MU_EARTH_M3PS2  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        return math.sqrt(MU_EARTH_M3PS2 / self.semi_major_axis_m**3)


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
    stall_timeout_s: float = 120.0     # [supervision]: lockstep's one wall-time decision (a stall)
    restart: str = "never"            # [supervision]: what the launcher does with a dead agent
    max_restarts: int = 3             # [supervision]: restarts per agent
    auth: bool = True                 # [security]: per-process credentials + ACL on the router (bus/acl.py)
    tls: bool = False                 # [security]: mutual TLS to the router, per-run certificates (bus/tls.py)
    decision_period_steps: int = 1
    sections: dict[str, Any] = field(default_factory=dict)  # raw tables for link, beacon, nav, viz
    spacecraft: list[Any] = field(default_factory=list)     # plant.bodies.SpacecraftSpec, one per id
    bodies: list[Any] = field(default_factory=list)         # plant.bodies.BodySpec
    actuator_limit: str = "per_axis"
    plant_options: dict[str, Any] = field(default_factory=dict)  # frame_origin, j2, atmospheric_drag, ...
    doc: dict[str, Any] = field(default_factory=dict)       # the document after --set, as validated
    sets: tuple[str, ...] = ()                              # the --set overrides applied
    epoch_utc: str = "2000-01-01T12:00:00Z"                 # t = 0 of the run (MCAP log_time = epoch + t)
    faults: list[Any] = field(default_factory=list)         # [[fault]]: plant.faults specs (issue 27)
    contact: Any = None                                     # [contact]: plant.contact.ContactConfig

    def spec(self, sc_id: str) -> Any:
        """The SpacecraftSpec of one spacecraft (generated ones get defaults)."""
        for s in self.spacecraft:
            if s.id == sc_id:
                return s
        raise KeyError(f"unknown spacecraft id {sc_id!r}")

    def controller_of(self, sc_id: str) -> tuple[str, dict[str, Any]]:
        """(controller name, params) of one spacecraft: its own, over the swarm's [controller]."""
        s = self.spec(sc_id)
        return (s.controller or self.controller), {**self.controller_params, **s.params}

    def resolved(self) -> dict[str, Any]:
        """The fully resolved configuration (defaults filled in), JSON-ready: what a recording carries."""
        from importlib.metadata import PackageNotFoundError, version

        from swarmhil.plant.faults import fault_summary  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            ver = version("swarmhil")
        except PackageNotFoundError:
            ver = "unknown"
        link = None
        if "link" in self.sections:
            from swarmhil.link.model import link_enabled, parse_link_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

            if link_enabled(self.sections["link"]):
                link = parse_link_config(self.sections["link"], self.source, self.seed).to_dict()
        return {
            "software_version": ver,
            "scenario_file": self.source,
            "sets": list(self.sets),
            "run": {"name": self.name, "duration_s": self.duration_s, "step_s": self.step_s, "seed": self.seed,
                    "mode": self.mode, "speed": self.speed, "steps": self.steps, "epoch_utc": self.epoch_utc,
                    # the rooms from outside the tree: `swarmhil report` imports their report parts
                    **({"rooms": list(rooms)} if (rooms := (self.doc.get("run") or {}).get("rooms")) else {})},
            "orbit": {"semi_major_axis_m": self.orbit.semi_major_axis_m,
                      "inclination_deg": math.degrees(self.orbit.inclination_rad),
                      "raan_deg": math.degrees(self.orbit.raan_rad), "u0_deg": math.degrees(self.orbit.u0_rad),
                      "mean_motion_radps": self.orbit.mean_motion_radps,
                      **({"eccentricity": self.orbit.eccentricity, "argp_deg": math.degrees(self.orbit.argp_rad)}
                         if self.orbit.eccentricity or self.orbit.argp_rad else {})},
            "plant": {"fidelity": self.fidelity, "drag": self.drag, **self.plant_options},
            "camera": dict(self.camera),
            "actuator": {"max_accel_mps2": self.max_accel_mps2, "limit": self.actuator_limit},
            "controller": {"name": self.controller, "params": self.controller_params,
                           "decision_period_s": self.decision_period_steps * self.step_s},
            "sensing": dict(self.sensing),
            "supervision": {"stall_timeout_s": self.stall_timeout_s, "restart": self.restart,
                            "max_restarts": self.max_restarts},
            "security": {"auth": self.auth, "tls": self.tls},
            "link": link,
            "beacon": self.sections.get("beacon"),
            "nav": self.sections.get("nav"),
            "viz": self.sections.get("viz"),
            "dispersion": self.sections.get("dispersion"),
            "spacecraft": [{**s.model_dump(), "roe_m": [float(x) for x in r]} for s, r in zip(self.spacecraft, self.roe_m)],
            "body": [b.model_dump() for b in self.bodies],
            "faults": [fault_summary(f) for f in self.faults],
            "contact": self.contact.model_dump() if self.contact is not None else None,
            "recovery": {"hold_s": self.recovery_hold_s},
        }

    @property
    def recovery_hold_s(self) -> float:
        """[recovery].hold_s: how long the swarm must stay whole after a fault to count as recovered
        (dashboards/sections/faults.py `judge`); default one period of the reference orbit, 2 pi / n."""
        hold = (self.sections.get("recovery") or {}).get("hold_s")
        return float(hold) if hold is not None else 2.0 * math.pi / self.orbit.mean_motion_radps

    @property
    def steps(self) -> int:
        return int(round(self.duration_s / self.step_s))

    def with_overrides(self, *, duration_s: float | None = None, seed: int | None = None,
                       mode: str | None = None, speed: float | None = None) -> "Scenario":
        import copy

        s = copy.copy(self)
        if duration_s is not None:
            s.duration_s = _positive(self.source, "--duration", duration_s)
            _check_steps(self.source, "--duration", s.duration_s, s.step_s)
            _check_fault_starts(self.source, getattr(s, "faults", ()) or (), s.duration_s, s.step_s, "--duration",
                                warn_only=True)
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63):
            raise _err(self.source, "--seed", "must be a non-negative integer", seed)
        if mode is not None:
            s.mode = _choice(self.source, "--mode", mode, ("lockstep", "realtime"))
        if speed is not None:
            s.speed = _positive(self.source, "--speed", speed)
        if seed is not None and seed != self.seed:
            s.seed = int(seed)
            if self.sections.get("_generated"):
                s.ids, s.roe_m = _generate(self.source, self.sections["dispersion"], s.seed, self)
                s.spacecraft = _generated_specs(s.ids, s.roe_m)
        return s


def _check_fault_starts(src: str, faults: Any, duration_s: float, step_s: float, flag: str,
                        warn_only: bool = False) -> None:
    """A fault that would start at or after the run's last step never fires: in the scenario file
    itself a scenario error naming it, not a run that exits 0 without it (issue 37); for a run
    shortened by --duration a warning (the report then says it never started)."""
    if not faults:
        return
    from swarmhil.plant.faults import FaultWindow  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    steps = int(round(duration_s / step_s))
    for f in faults:
        if FaultWindow.of(f, step_s).start_step >= steps:
            if warn_only:
                logging.getLogger("swarmhil.deploy").warning(
                    "%s: [[fault]] %r starts at %g s, at or after the end of this run (%s = %g s): it will not fire",
                    src, f.name, f.start_s, flag, duration_s)
                continue
            raise ScenarioError(f"{src}: [[fault]] {f.name!r} starts at {f.start_s:g} s, at or after the end of the run "
                                f"({flag} = {duration_s:g} s): it would never fire")


DEFAULT_EPOCH_UTC = "2000-01-01T12:00:00Z"


def _epoch(src: str, value: Any) -> str:
    """[run].epoch_utc: an ISO 8601 date-time (UTC if it names no offset), normalised to `...Z`."""
    from datetime import datetime, timezone

    if isinstance(value, str):
        try:
            dt = datetime.fromisoformat(value)
        except ValueError:
            raise _err(src, "[run].epoch_utc", "must be an ISO 8601 date-time, e.g. 2000-01-01T12:00:00Z", value) from None
    else:
        raise _err(src, "[run].epoch_utc", "must be an ISO 8601 date-time as a quoted string", value)
    dt = dt.replace(tzinfo=timezone.utc) if dt.tzinfo is None else dt.astimezone(timezone.utc)
    if dt.year < 1970:
        raise _err(src, "[run].epoch_utc", "must not be before 1970 (MCAP times are unsigned ns since 1970)", value)
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + (f".{dt.microsecond:06d}" if dt.microsecond else "") + "Z"


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


MAX_STEPS = 10_000_000  # about 3 years of 10 s steps; a run longer than that is a typo


def _check_steps(src: str, where: str, duration: float, step: float) -> None:
    if duration < step:
        raise _err(src, where, f"must be at least one step ({step} s)", duration)
    if duration / step > MAX_STEPS:
        raise _err(src, where, f"gives {duration / step:.3g} steps of {step} s; at most {MAX_STEPS} are allowed", duration)


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


def load_scenario(path: str | Path, sets: list[str] | tuple[str, ...] = (), *, flight_software: bool = True) -> Scenario:
    """Read a scenario (TOML, or the JSON a launcher writes for its children: {"source", "doc",
    "sets"}), apply `--set` overrides, validate. `flight_software=False`: a ground process (the
    plant, the recorder, a companion) reading the launcher's already validated document: the
    controllers' names and parameters are taken as written, and no flight software is imported to
    check them (the plant process never loads a controller; tests/test_imports.py)."""
    from swarmhil.deploy.overrides import OverrideError, apply_sets  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    doc, src, applied = read_document(path)
    try:
        doc = apply_sets(doc, list(sets))
    except OverrideError as exc:
        raise ScenarioError(f"{src}: {exc}") from None
    sc = parse_scenario(doc, src, flight_software=flight_software)
    sc.sets = applied + tuple(sets)
    return sc


def read_document(path: str | Path) -> tuple[dict[str, Any], str, tuple[str, ...]]:
    """(document, source name, --set already applied) of a scenario file, not yet validated; a file
    that cannot be read, is not UTF-8 or not TOML is a ScenarioError naming it."""
    import json

    p = Path(path)
    src = p.name
    try:
        text = p.read_text(encoding="utf-8")
    except IsADirectoryError:
        raise ScenarioError(f"{path}: is a directory, not a scenario file") from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read scenario ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{src}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    applied: tuple[str, ...] = ()
    if p.suffix == ".json":
        try:
            wrapped = json.loads(text)
            doc, src, applied = wrapped["doc"], wrapped["source"], tuple(wrapped.get("sets", ()))
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise ScenarioError(f"{src}: not a resolved scenario document ({exc})") from None
    else:
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError(f"{src}: not valid TOML: {exc}") from None
    return doc, src, applied


def resolved_document(sc: Scenario) -> dict[str, Any]:
    """What a launcher hands its children: the validated document after --set (JSON-ready)."""
    return {"source": sc.source, "sets": list(sc.sets), "doc": sc.doc}


def plant_config(sc: Scenario) -> Any:
    """The plant's configuration (plant/config.py PlantConfig): what of the scenario the plant reads,
    frozen; the plant is given this, never the Scenario (the agent's counterpart is agent_config)."""
    from swarmhil.plant.config import PlantConfig, PlantOrbit, freeze  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    o = sc.orbit
    roe = np.array(sc.roe_m, dtype=float)
    roe.setflags(write=False)
    return PlantConfig(
        ids=tuple(sc.ids), steps=sc.steps, step_s=sc.step_s, seed=sc.seed, mode=sc.mode,  # type: ignore[arg-type]
        speed=sc.speed, stall_timeout_s=sc.stall_timeout_s,
        orbit=PlantOrbit(semi_major_axis_m=o.semi_major_axis_m, inclination_rad=o.inclination_rad,
                         raan_rad=o.raan_rad, u0_rad=o.u0_rad, mean_motion_radps=o.mean_motion_radps,
                         eccentricity=o.eccentricity, argp_rad=o.argp_rad),
        fidelity=sc.fidelity, drag=freeze(sc.drag), max_accel_mps2=sc.max_accel_mps2,
        actuator_limit=sc.actuator_limit, plant_options=freeze(sc.plant_options), roe_m=roe,
        spacecraft=tuple(sc.spacecraft), bodies=tuple(sc.bodies), camera=freeze(sc.camera),
        sensing=freeze(sc.sensing), controllers=tuple((c, freeze(p)) for c, p in map(sc.controller_of, sc.ids)),
        faults=tuple(sc.faults), contact=sc.contact)


def parse_scenario(doc: dict[str, Any], src: str = "<scenario>", *, flight_software: bool = True) -> Scenario:
    """Validate a scenario document (`flight_software`: as load_scenario)."""
    unknown = sorted(set(doc) - SECTIONS)
    if unknown:
        raise _err(src, f"[{unknown[0]}]", f"is not a known section; known: {sorted(SECTIONS)}", "…")
    run = _table(src, doc, "run", {"name", "duration_s", "step_s", "seed", "mode", "speed", "description", "plugins",
                                   "epoch_utc", "rooms"})
    _import_plugins(src, run.get("plugins", []))
    _add_rooms(src, run.get("rooms", []))
    name = check_name(src, run.get("name", Path(src).stem))
    duration = _positive(src, "[run].duration_s", run.get("duration_s", 600.0))
    step = _positive(src, "[run].step_s", run.get("step_s", 10.0))
    _check_steps(src, "[run].duration_s", duration, step)
    seed = run.get("seed", 1)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise _err(src, "[run].seed", "must be a non-negative integer", seed)
    mode = _choice(src, "[run].mode", run.get("mode", "lockstep"), ("lockstep", "realtime"))
    speed = _positive(src, "[run].speed", run.get("speed", 1.0))
    epoch_utc = _epoch(src, run.get("epoch_utc", DEFAULT_EPOCH_UTC))

    o = _table(src, doc, "orbit", {"semi_major_axis_m", "inclination_deg", "raan_deg", "u0_deg", "eccentricity",
                                   "argp_deg"})
    orbit = OrbitCfg(
        semi_major_axis_m=_num(src, "[orbit].semi_major_axis_m", o.get("semi_major_axis_m", 6878137.0), lo=6378137.0 + 100e3),
        inclination_rad=math.radians(_num(src, "[orbit].inclination_deg", o.get("inclination_deg", 97.4), 0, 180)),
        raan_rad=math.radians(_num(src, "[orbit].raan_deg", o.get("raan_deg", 0.0))),
        u0_rad=math.radians(_num(src, "[orbit].u0_deg", o.get("u0_deg", 0.0))),
        eccentricity=_num(src, "[orbit].eccentricity", o.get("eccentricity", 0.0), 0.0, 0.9),
        argp_rad=math.radians(_num(src, "[orbit].argp_deg", o.get("argp_deg", 0.0))),
    )
    pl = _table(src, doc, "plant", {"fidelity", "drag", "frame_origin", "j2", "atmospheric_drag",
                                    "max_integration_step_s", "command_frame"})
    fidelity = _choice(src, "[plant].fidelity", pl.get("fidelity", "linear"), PROPAGATORS)
    if (orbit.eccentricity or orbit.argp_rad) and fidelity != "inertial":
        raise _err(src, "[orbit].eccentricity", "and argp_deg need [plant] fidelity = 'inertial' (the other "
                                                "propagators fly a circular reference)", o.get("eccentricity"))
    if orbit.semi_major_axis_m * (1.0 - orbit.eccentricity) < 6378137.0 + 100e3:
        raise _err(src, "[orbit].eccentricity", "puts the periapsis below 100 km altitude", orbit.eccentricity)
    drag = _drag(src, pl.get("drag"))
    plant_options = _plant_options(src, pl, fidelity)
    cam = _table(src, doc, "camera", {"detection_range_m", "image_px", "focal_px"})
    camera = {
        "detection_range_m": _positive(src, "[camera].detection_range_m", cam.get("detection_range_m", 500.0)),
        "image_px": int(_positive(src, "[camera].image_px", cam.get("image_px", 1080))),
        "focal_px": _positive(src, "[camera].focal_px", cam.get("focal_px", 1000.0)),
    }
    act = _table(src, doc, "actuator", {"max_accel_mps2", "limit"})
    max_accel = _positive(src, "[actuator].max_accel_mps2", act.get("max_accel_mps2", 1e-3))
    limit = _choice(src, "[actuator].limit", act.get("limit", "per_axis"), ("per_axis", "norm"))
    ctl = _table(src, doc, "controller", {"name", "params", "decision_period_s"})
    controller = _controller(src, "[controller].name", ctl.get("name", "null"), flight_software)
    params = ctl.get("params", {})
    if not isinstance(params, dict):
        raise _err(src, "[controller].params", "must be a table", params)
    params = {"max_accel_mps2": max_accel, **params}
    if flight_software:
        _check_params(src, "[controller.params]", controller, params)
    decision_period = _positive(src, "[controller].decision_period_s", ctl.get("decision_period_s", step))
    decision_steps = int(round(decision_period / step))
    if decision_steps < 1 or abs(decision_steps * step - decision_period) > 1e-9 * decision_period:
        raise _err(src, "[controller].decision_period_s", f"must be a whole number of steps of {step} s", decision_period)
    sens = _table(src, doc, "sensing", {"kind", "roe_noise_fraction", "pointing_error_rad", "pointing_jitter_rad",
                                        "params"})
    from swarmhil.plant.sensing import known_sensing, validate_sensing_params  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    sensing: dict[str, Any] = {
        "kind": _choice(src, "[sensing].kind", sens.get("kind", "rel"), tuple(known_sensing())),
        "roe_noise_fraction": _num(src, "[sensing].roe_noise_fraction", sens.get("roe_noise_fraction", 0.0), 0.0, 10.0),
        "pointing_error_rad": _vec3(src, "[sensing].pointing_error_rad", sens.get("pointing_error_rad", [0.0, 0.0, 0.0])),
        "pointing_jitter_rad": _num(src, "[sensing].pointing_jitter_rad", sens.get("pointing_jitter_rad", 0.0), 0.0, 0.1),
    }
    sparams = sens.get("params", {})
    if not isinstance(sparams, dict):
        raise _err(src, "[sensing.params]", "must be a table", sparams)
    try:
        validate_sensing_params(sensing["kind"], sparams)
    except ValueError as exc:
        raise ScenarioError(f"{src}: [sensing.params] (kind {sensing['kind']!r}): {_one_line(exc)}") from None
    if sparams:
        sensing["params"] = dict(sparams)
    if sensing["kind"] == "scene":
        from swarmhil.agent.perception import nav_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            nav_config(doc.get("nav"))
        except ValueError as exc:
            raise ScenarioError(f"{src}: {exc}") from None
    stall, restart, max_restarts = _supervision(src, doc)
    auth, tls = _security(src, doc)

    _beacon(src, doc)
    _viz(src, doc)
    _recovery(src, doc)
    sc = Scenario(
        name=name, source=src, duration_s=duration, step_s=step, seed=seed, mode=mode, speed=speed,
        orbit=orbit, fidelity=fidelity, drag=drag, camera=camera, max_accel_mps2=max_accel,
        controller=controller, controller_params=params, sensing=sensing, ids=[], roe_m=np.zeros((0, 6)),
        stall_timeout_s=stall, restart=restart, max_restarts=max_restarts, auth=auth, tls=tls,
        decision_period_steps=decision_steps,
        sections={k: doc[k] for k in ("link", "beacon", "nav", "viz", "dispersion", "recovery") if k in doc},
        actuator_limit=limit, doc=doc, plant_options=plant_options, epoch_utc=epoch_utc,
    )
    if "link" in doc:
        from swarmhil.link.model import LinkConfigError, parse_link_config  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            parse_link_config(doc["link"], src, seed)
        except LinkConfigError as exc:
            raise ScenarioError(str(exc)) from None
    if "spacecraft" in doc:
        sc.spacecraft = _explicit(src, doc["spacecraft"])
        sc.ids = [s.id for s in sc.spacecraft]
        sc.roe_m = _initial_roe(sc)
        for s in sc.spacecraft:
            if s.controller is not None:
                name_ = _controller(src, f"[[spacecraft]] {s.id}.controller", s.controller, flight_software)
                if flight_software:
                    _check_params(src, f"[[spacecraft]] {s.id}.params", name_, {**params, **s.params})
    elif "dispersion" in doc:
        sc.sections["_generated"] = True
        sc.ids, sc.roe_m = _generate(src, doc["dispersion"], seed, sc)
        sc.spacecraft = _generated_specs(sc.ids, sc.roe_m)
    else:
        raise ScenarioError(f"{src}: no spacecraft: give [[spacecraft]] tables (id, roe_m) or a [dispersion] table")
    sc.bodies = _bodies(src, doc.get("body", []), set(sc.ids))
    sc.contact = _contact(src, doc.get("contact", {}))
    if "fault" in doc:
        from swarmhil.plant.faults import FaultError, parse_faults  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

        try:
            sc.faults = parse_faults(src, doc["fault"], sc.ids, step, {b.id: b.motion.kind for b in sc.bodies})
        except FaultError as exc:
            raise ScenarioError(str(exc)) from None
        _check_fault_starts(src, sc.faults, sc.duration_s, step, "[run].duration_s")
    cartesian = fidelity in ("cw", "inertial")
    if not cartesian and (sc.bodies or any(s.inertia_kgm2 is not None for s in sc.spacecraft)):
        raise _err(src, "[plant].fidelity", "must be 'cw' or 'inertial' for [[body]] tables or attitude "
                                            "(inertia_kgm2)", fidelity)
    origin = plant_options.get("frame_origin", "reference")
    if origin != "reference" and origin not in sc.ids + [b.id for b in sc.bodies if b.motion.kind == "propagated"]:
        raise _err(src, "[plant].frame_origin", "must be 'reference', a spacecraft id or a propagated body id", origin)
    return sc


def _contact(src: str, table: Any) -> Any:
    """[contact] (plant/contact.py): hard-body radius default, keep-out distance, point masses."""
    from pydantic import ValidationError

    from swarmhil.plant.bodies import format_validation_error  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.contact import ContactConfig  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if not isinstance(table, dict):
        raise _err(src, "[contact]", "must be a table", table)
    try:
        return ContactConfig.model_validate(table)
    except ValidationError as exc:
        raise ScenarioError(format_validation_error(src, "[contact]", exc, ContactConfig)) from None


def _recovery(src: str, doc: dict[str, Any]) -> None:
    """[recovery]: hold_s, how long (simulated seconds) the swarm must stay whole after a fault for
    the fault to count as recovered (docs/faults.md); omitted: one orbit period."""
    t = _table(src, doc, "recovery", {"hold_s"})
    if "hold_s" in t:
        _num(src, "[recovery].hold_s", t["hold_s"], 0.0, 86400.0 * 365)


def _supervision(src: str, doc: dict[str, Any]) -> tuple[float, str, int]:
    """[supervision]: stall_timeout_s (lockstep waits for every live process; a step open this long
    on the wall clock is a stall, an error event), restart ("never" | "on-failure": a dead agent is
    restarted and rejoins cold) and max_restarts (per agent). The old `[time].lockstep_timeout_s`
    is read as the stall timeout; `[time].dead_after_missed` is gone (a slow live agent is waited
    for, a dead one is dropped when its liveliness token goes: docs/reliability.md)."""
    tm = _table(src, doc, "time", {"lockstep_timeout_s", "dead_after_missed"})
    if "dead_after_missed" in tm:
        raise _err(src, "[time].dead_after_missed", "is no more: lockstep waits for a live agent and drops a dead "
                                                    "one at once; see [supervision].stall_timeout_s", tm["dead_after_missed"])
    sup = _table(src, doc, "supervision", {"stall_timeout_s", "restart", "max_restarts"})
    if "lockstep_timeout_s" in tm and "stall_timeout_s" in sup:
        raise _err(src, "[time].lockstep_timeout_s", "is the old name of [supervision].stall_timeout_s; give one",
                   tm["lockstep_timeout_s"])
    stall = _num(src, "[supervision].stall_timeout_s", sup.get("stall_timeout_s", tm.get("lockstep_timeout_s", 120.0)),
                 0.1, 86400.0 * 7)
    restart = _choice(src, "[supervision].restart", sup.get("restart", "never"), RESTART_POLICIES)
    max_restarts = sup.get("max_restarts", 3)
    if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or not 0 <= max_restarts <= 1000:
        raise _err(src, "[supervision].max_restarts", "must be an integer in 0..1000", max_restarts)
    return float(stall), restart, max_restarts


def _security(src: str, doc: dict[str, Any]) -> tuple[bool, bool]:
    """[security] of a multi-process run (docs/reliability.md): `auth` (default true: one
    credential per process, usrpwd authentication and the per-key ACL on the router) and `tls`
    (default false: mutual TLS on every link to the router with the run's own CA). TLS names a
    process by its credential's user, so `tls = true` needs `auth = true`. The command line's
    `--insecure` / `--tls` override the file. An in-process run has no network: both are moot."""
    sec = _table(src, doc, "security", {"auth", "tls"})
    for key in ("auth", "tls"):
        if key in sec and not isinstance(sec[key], bool):
            raise _err(src, f"[security].{key}", "must be true or false", sec[key])
    auth, tls = sec.get("auth", True), sec.get("tls", False)
    if tls and not auth:
        raise _err(src, "[security].tls", "needs [security].auth = true (TLS names each process by its credential)", tls)
    return auth, tls


def _import_plugins(src: str, plugins: Any) -> None:
    """[run].plugins: modules every process imports before building anything (a mission or a test
    outside the source tree registers its controllers, sensing kinds and propagators there)."""
    import importlib

    if not isinstance(plugins, list) or not all(isinstance(m, str) for m in plugins):
        raise _err(src, "[run].plugins", "must be a list of module names", plugins)
    for m in plugins:
        try:
            importlib.import_module(m)
        except Exception as exc:  # noqa: BLE001 - any import failure is a configuration error here
            raise _err(src, "[run].plugins", f"module {m!r} does not import ({type(exc).__name__}: {exc})", m) from None


def _add_rooms(src: str, rooms: Any) -> None:
    """[run].rooms: mission rooms outside the source tree (packages laid out like missions/<room>/:
    contract, fsw, sense, report; docs/adding-a-mission.md). Each process imports its own part of
    them, as of the rooms in the tree (bus/discovery.py `add_rooms`, `import_role`)."""
    if not isinstance(rooms, list) or not all(isinstance(m, str) and m for m in rooms):
        raise _err(src, "[run].rooms", "must be a list of package names", rooms)
    try:
        add_rooms(rooms)
    except RoomError as exc:
        raise _err(src, "[run].rooms", str(exc), rooms) from None


def _plant_options(src: str, pl: dict[str, Any], fidelity: str) -> dict[str, Any]:
    """[plant] options of the Cartesian propagators (plant/mission_world.py)."""
    out: dict[str, Any] = {}
    if "frame_origin" in pl:
        if not isinstance(pl["frame_origin"], str):
            raise _err(src, "[plant].frame_origin", "must be 'reference' or an id", pl["frame_origin"])
        out["frame_origin"] = pl["frame_origin"]
    for flag in ("j2", "atmospheric_drag"):
        if flag in pl:
            if not isinstance(pl[flag], bool):
                raise _err(src, f"[plant].{flag}", "must be true or false", pl[flag])
            out[flag] = pl[flag]
    if "max_integration_step_s" in pl:
        out["max_integration_step_s"] = _positive(src, "[plant].max_integration_step_s", pl["max_integration_step_s"])
    if "command_frame" in pl:
        # "lvlh" (default): accel commands in the scenario frame (the origin's LVLH); "eci": ECI axes,
        # applied as such (plant/mission_world.py); the Truth's accel_cmd_mps2 stays in the scenario frame
        out["command_frame"] = _choice(src, "[plant].command_frame", pl["command_frame"], ("lvlh", "eci"))
    inertial_only = sorted(k for k in set(out) - {"frame_origin"} if not (k == "command_frame" and out[k] == "lvlh"))
    if inertial_only and fidelity != "inertial":
        raise _err(src, "[plant]", f"options {inertial_only} need fidelity = 'inertial'", fidelity)
    return out


def _generated_specs(ids: list[str], roe_m: np.ndarray) -> list[Any]:
    from swarmhil.plant.bodies import SpacecraftSpec  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    return [SpacecraftSpec(id=i, roe_m=[float(x) for x in r]) for i, r in zip(ids, roe_m)]


def _initial_roe(sc: Scenario) -> np.ndarray:
    """(N,6) ROE of every spacecraft: given, or mapped from a Cartesian LVLH state (exact inverse of
    the linear map the `linear` and `j2` plants start from)."""
    from swarmhil.plant.dynamics.roe_linear import lvlh_to_roe  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    rows = []
    for s in sc.spacecraft:
        if s.roe_m is not None:
            rows.append(np.asarray(s.roe_m, float))
        else:
            rows.append(lvlh_to_roe(np.asarray([s.position_m], float), np.asarray([s.velocity_mps], float),
                                    sc.orbit.u0_rad, sc.orbit.mean_motion_radps)[0])
    return np.array(rows).reshape(-1, 6)


def _one_line(exc: Exception) -> str:
    """A validation error on one line (pydantic's multi-line text folded)."""
    errors = getattr(exc, "errors", None)
    if callable(errors):
        try:
            return "; ".join(f"{'.'.join(str(x) for x in e['loc'])}: {e['msg']} (got {e.get('input')!r})" for e in errors())
        except Exception:  # noqa: BLE001 - fall back to the text
            pass
    return " ".join(str(exc).split())


def _controller(src: str, where: str, name: Any, flight_software: bool) -> str:
    """A controller's name: one of the catalogue's (which imports every room's flight software), or,
    in a ground process (`flight_software=False`), any non-empty name as the launcher validated it."""
    if not flight_software:
        if not isinstance(name, str) or not name:
            raise _err(src, where, "must be a controller name", name)
        return name
    from swarmhil.agent.catalogue import known_controllers  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    return _choice(src, where, name, tuple(known_controllers()))


def _check_params(src: str, where: str, controller: str, params: dict[str, Any]) -> None:
    """Validate a controller's params with the check its registration provides (agent/controller.py)."""
    from swarmhil.agent.catalogue import validate_params  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    try:
        validate_params(controller, params)
    except (ValueError, TypeError) as exc:
        raise ScenarioError(f"{src}: {where} (controller {controller!r}): {_one_line(exc)}") from None


def _drag(src: str, drag: Any) -> dict[str, Any] | None:
    """[plant].drag: ballistic_coefficient_m2pkg (documented name; bc_m2pkg accepted), optional
    reference coefficient and atmosphere; validated here, not at plant start."""
    if drag is None:
        return None
    if not isinstance(drag, dict):
        raise _err(src, "[plant].drag", "must be a table (ballistic_coefficient_m2pkg, ...) or absent", drag)
    aliases = {"ballistic_coefficient_m2pkg": "bc_m2pkg", "reference_ballistic_coefficient_m2pkg": "bc_ref_m2pkg"}
    known = {"bc_m2pkg", "bc_ref_m2pkg", "rho0_kgpm3", "h0_m", "scale_height_m", "rotating_atmosphere"} | set(aliases)
    unknown = sorted(set(drag) - known)
    if unknown:
        raise _err(src, f"[plant].drag.{unknown[0]}", f"is not a known field; known: {sorted(known)}", drag[unknown[0]])
    out: dict[str, Any] = {}
    for k, v in drag.items():
        name = str(aliases.get(k, k))  # TOML keys are strings
        if name == "rotating_atmosphere":
            if not isinstance(v, bool):
                raise _err(src, f"[plant].drag.{k}", "must be true or false", v)
            out[name] = v
        elif name == "bc_m2pkg" and isinstance(v, list):
            out[name] = [_num(src, f"[plant].drag.{k}[{i}]", x, lo=0.0) for i, x in enumerate(v)]
        else:
            out[name] = _num(src, f"[plant].drag.{k}", v, lo=0.0)
    if "bc_m2pkg" not in out:
        raise _err(src, "[plant].drag.ballistic_coefficient_m2pkg", "is required (C_D A / m, m^2/kg)", None)
    return out


def _beacon(src: str, doc: dict[str, Any]) -> None:
    t = _table(src, doc, "beacon", {"enabled", "period_s", "include_estimates"})
    if not t:
        return
    if not isinstance(t.get("enabled", True), bool):
        raise _err(src, "[beacon].enabled", "must be true or false", t["enabled"])
    if "period_s" not in t and t.get("enabled", True):
        raise _err(src, "[beacon].period_s", "is required when [beacon] is enabled", None)
    if "period_s" in t:
        _positive(src, "[beacon].period_s", t["period_s"])
    if not isinstance(t.get("include_estimates", False), bool):
        raise _err(src, "[beacon].include_estimates", "must be true or false", t["include_estimates"])


def _viz(src: str, doc: dict[str, Any]) -> None:
    t = _table(src, doc, "viz", {"trail_s"})
    if "trail_s" in t:
        _positive(src, "[viz].trail_s", t["trail_s"])


def _bodies(src: str, items: Any, ids: set[str]) -> list[Any]:
    from pydantic import ValidationError

    from swarmhil.plant.bodies import BodySpec, format_validation_error  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if not isinstance(items, list):
        raise _err(src, "[[body]]", "must be an array of tables", items)
    out: list[BodySpec] = []
    for i, item in enumerate(items):
        try:
            b = BodySpec.model_validate(item)
        except ValidationError as exc:
            raise ScenarioError(format_validation_error(src, f"[[body]][{i}]", exc, BodySpec)) from None
        if b.id in ids or b.id in {o.id for o in out}:
            raise _err(src, f"[[body]][{i}].id", "is a duplicate of a spacecraft or body id", b.id)
        out.append(b)
    return out


def check_name(src: str, name: Any) -> str:
    try:
        return check_token(name, "run name")
    except ValueError as exc:
        raise _err(src, "[run].name", str(exc), name) from None


def _explicit(src: str, items: Any) -> list[Any]:
    from pydantic import ValidationError

    from swarmhil.plant.bodies import SpacecraftSpec, format_validation_error  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

    if not isinstance(items, list) or not items:
        raise _err(src, "[[spacecraft]]", "must be a non-empty array of tables", items)
    specs: list[Any] = []
    for i, item in enumerate(items):
        where = f"[[spacecraft]][{i}]"
        if not isinstance(item, dict):
            raise _err(src, where, "must be a table", item)
        if "id" not in item:
            raise _err(src, f"{where}.id", "is required", None)
        try:
            spec = SpacecraftSpec.model_validate(item)
        except ValidationError as exc:
            raise ScenarioError(format_validation_error(src, where, exc, SpacecraftSpec)) from None
        if spec.id in {s.id for s in specs}:
            raise _err(src, f"{where}.id", "is a duplicate", spec.id)
        specs.append(spec)
    return specs


def _generate(src: str, d: Any, seed: int, sc: Scenario) -> tuple[list[str], np.ndarray]:
    from swarmhil.plant.dispersion import Dispersion, draw_roe  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.dynamics.roe_linear import roe_to_lvlh  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)
    from swarmhil.plant.sensors import CameraGeometry, visible_pairs, weakly_connected_pairs  # on use: a command or role loads what it runs (start-up; tests/test_imports.py)

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
    tries = d.get("max_tries", 2000)
    if isinstance(tries, bool) or not isinstance(tries, int) or not 1 <= tries <= 1_000_000:
        raise _err(src, "[dispersion].max_tries", "must be an integer in 1..1000000", tries)
    cam = CameraGeometry(sc.camera["detection_range_m"], int(sc.camera["image_px"]), sc.camera["focal_px"])
    for _ in range(tries):
        roe = draw_roe(rng, disp)
        if not want_connected:
            return ids, roe
        pos, _v = roe_to_lvlh(roe, sc.orbit.u0_rad, sc.orbit.mean_motion_radps)
        if weakly_connected_pairs(count, *visible_pairs(pos, cam)):  # (the visibility digraph's pairs)
            return ids, roe
    raise _err(src, "[dispersion]", f"gave no weakly connected initial swarm in {tries} draws; widen or tighten it", d)
