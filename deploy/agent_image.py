"""What one spacecraft's flight-software image is built from: a small JSON-ready config per agent.

The launcher validates the scenario once (deploy/scenario.py: pydantic, every mission's registry,
the dispersion draw) and writes each agent's config into DIR/scenario.json under "agents". An agent
process reads only its own entry and builds its node from it (`build_agent`), so it imports neither
the scenario validation (pydantic, scipy) nor the launcher (tqdm), nor the missions it does not fly:
an ideal-sensing agent stays under 60 MB RSS (docs/performance.md "Agent memory and imports").
In-process runs build their agents from the same configs (after the same JSON round trip), so both
modes run identical flight software.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def agent_config(sc: Any, sid: str) -> dict[str, Any]:
    """Everything spacecraft `sid`'s flight software is configured with, from a validated Scenario,
    as plain JSON data (round-tripped, so in-process and multi-process agents get equal values)."""
    from swarmhil.agent.catalogue import controller_module  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)
    controller, params = sc.controller_of(sid)
    nav = None
    if sc.sensing["kind"] == "scene":  # the camera pipeline (and scipy) only for the scene stimulus
        from swarmhil.agent.perception import nav_config  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)

        nav = nav_config(sc.sections.get("nav"))
    cfg = {
        "id": sid,
        "plugins": list(sc.doc.get("run", {}).get("plugins", [])),
        "controller": controller,
        "controller_module": controller_module(controller),
        "params": params,
        "orbit": {"semi_major_axis_m": sc.orbit.semi_major_axis_m, "mean_motion_radps": sc.orbit.mean_motion_radps},
        "sense_kind": sc.sensing["kind"],
        "decision_period_steps": sc.decision_period_steps,
        "beacon": sc.sections.get("beacon"),
        "nav": nav,
        "camera": dict(sc.camera),
    }
    return json.loads(json.dumps(cfg))


def agent_configs(sc: Any) -> dict[str, dict[str, Any]]:
    """{id: agent_config} for every spacecraft (the "agents" entry of DIR/scenario.json).

    Also builds, here in the launcher, one controller of each distinct configuration: whatever a
    controller computes once and caches on disk at construction (the DRE gain tables of
    missions/p002_sabatini/fsw/dre.py, solved with scipy) is then there before the agents start, so no agent
    solves it (nor imports scipy), even on a machine's first run."""
    from swarmhil.agent.catalogue import make_controller  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)
    from swarmhil.agent.controller import OrbitInfo  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)

    configs = {sid: agent_config(sc, sid) for sid in sc.ids}
    seen: set[str] = set()
    for cfg in configs.values():
        key = json.dumps([cfg["controller"], cfg["params"], cfg["orbit"]], sort_keys=True)
        if key not in seen:
            seen.add(key)
            o = cfg["orbit"]
            make_controller(cfg["controller"], cfg["id"], OrbitInfo(o["semi_major_axis_m"], o["mean_motion_radps"]),
                            cfg["params"])
    return configs


def write_resolved_scenario(sc: Any, path: str | Path) -> Path:
    """What a launcher (or `swarmhil compose`) hands every child: the validated document after --set
    and each agent's config under "agents" (deploy/scenario.py reads the document part)."""
    from swarmhil.deploy.scenario import resolved_document  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)

    p = Path(path)
    p.write_text(json.dumps({**resolved_document(sc), "agents": agent_configs(sc)}, indent=1))
    return p


def read_agent_config(path: str | Path, sid: str) -> dict[str, Any] | None:
    """Agent `sid`'s config from a launcher-written DIR/scenario.json, or None when the file has no
    "agents" entry for it (a TOML scenario, as compose deployments pass: then validate it in full)."""
    p = Path(path)
    if p.suffix != ".json":
        return None
    try:
        agents = json.loads(p.read_text(encoding="utf-8")).get("agents") or {}
    except (OSError, ValueError, AttributeError):
        return None
    return agents.get(sid)


def build_agent(bus: Any, run: str, cfg: dict[str, Any]) -> Any:
    """One spacecraft's flight software (agent/node.py AgentNode) on a bus, from its config."""
    import importlib

    from swarmhil.agent.beacon import beacon_from_config  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)
    from swarmhil.agent.controller import OrbitInfo  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)
    from swarmhil.agent.node import AgentNode  # loaded by the side that runs it: the launcher or the agent role (tests/test_imports.py)

    for m in cfg["plugins"]:  # [run].plugins may register controllers
        importlib.import_module(m)
    importlib.import_module(cfg["controller_module"])  # registers the controller, and only that module
    o = cfg["orbit"]
    orbit = OrbitInfo(o["semi_major_axis_m"], o["mean_motion_radps"])
    perception = None
    if cfg["sense_kind"] == "scene":
        from swarmhil.agent.perception import Perception  # scene sensing only: camera, navigation and scipy

        perception = Perception(orbit.semi_major_axis_m, orbit.mean_motion_radps, cfg["nav"], cfg["camera"])
    return AgentNode(bus, run, cfg["id"], controller=cfg["controller"], orbit=orbit, params=cfg["params"],
                     sense_kind=cfg["sense_kind"], beacon=beacon_from_config(cfg["beacon"], cfg["id"]), perception=perception,
                     decision_period_steps=cfg["decision_period_steps"])
