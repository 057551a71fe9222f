"""What one step of paper 001's batch run (tersoff-6) costs, item by item, in microseconds (issue 29).

    nice -n 10 .venv/bin/python bench/p001_step_costs.py [--at 300] [--repeats 7]

Builds the in-process batch run of deploy/scenarios/tersoff-6.toml as deploy/launcher.py
`run_in_process(record="truth")` does (memory bus, recorder, `BatchHook`, plant), steps it to step
`--at` (every spacecraft far, nobody in the 21 m sensing ball: the first 3000 s), then times each
item of a step on that state with `timeit` (the best of `--repeats` rounds: these are the items'
costs hot, in a loop of their own; inside the run's loop each costs about 1.5 times more, the
caches shared with everything else), and beside them the whole step in the run's loop and the
vectorised floor's step (bench/mission_floors.py) over the same 600 steps, the minimum of
`--repeats` alternations. Not a test: figures for docs/performance.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import timeit
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--at", type=int, default=300, help="step at which the items are timed")
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args()
    from mission_floors import floor

    from swarmhil.bus.memory import MemoryBus
    from swarmhil.bus.recorder import RecorderNode
    from swarmhil.deploy.batch import BatchHook
    from swarmhil.deploy.launcher import run_in_process
    from swarmhil.deploy.scenario import load_scenario, plant_config
    from swarmhil.plant.node import PlantNode
    from swarmhil.plant.sensing.registry import SensingContext

    print(f"load average {os.getloadavg()[0]:.2f}", flush=True)
    sc = load_scenario(ROOT / "deploy" / "scenarios" / "tersoff-6.toml")
    with tempfile.TemporaryDirectory(prefix="p001-costs-") as tmp:
        bus = MemoryBus()
        long = sc.with_overrides(duration_s=40000.0)
        rec = RecorderNode(bus, "b", Path(tmp) / "run.mcap", config=long.resolved(), record="truth", background=True)
        hook = BatchHook(bus, "b", long)
        plant = PlantNode(bus, "b", plant_config(long), expect_processes=("recorder",), local_agents=hook)
        plant.wait_ready(timeout_s=1.0)
        for _ in range(a.at):
            plant.publish_step()
            plant.collect_and_advance()
        w = plant.world
        pos, vel = w.lvlh()
        ctx = SensingContext(step=a.at, t_s=w.t_s, u_rad=w.u_rad, ids=w.ids, position_m=pos, velocity_mps=vel,
                             alive=w.alive, world=w)
        rows = plant._all_rows
        roe = w.roe_m((pos, vel))
        hdr = plant._truth_header(a.at, w.t_s, a.at)
        data = plant._truth_wire.encode(hdr, w.u_rad, w.a_m, w.n_radps, pos, vel, w.delta_v_mps, w.alive,
                                        w.last_accel_mps2, roe)
        rel = plant.sensor.batch(ctx, rows)
        ob = hook._observe(ctx, rows, hook.ids, lambda: rel)
        ctrls = hook.agents.controllers
        cmd = hook.agents.accel_mps2.copy()
        items = {  # what a step does (plant/node.py publish_step, collect_and_advance), in its order
            "scenario-frame states (world.lvlh)": lambda: w.lvlh(),
            "truth ROE (world.roe_m)": lambda: w.roe_m((pos, vel)),
            "truth header (HeaderEncoder)": lambda: plant._truth_header(a.at, w.t_s, a.at),
            "truth bytes (TruthEncoder.encode)": lambda: plant._truth_wire.encode(
                hdr, w.u_rad, w.a_m, w.n_radps, pos, vel, w.delta_v_mps, w.alive, w.last_accel_mps2, roe),
            "truth to the recorder (MemoryBus.publish)": lambda: bus.publish(plant._k_truth, data, 1),
            "contact check (ContactMonitor.check)": lambda: plant.contact.check(a.at, w.t_s, pos, []),
            "sensing context": lambda: SensingContext(step=a.at, t_s=w.t_s, u_rad=w.u_rad, ids=w.ids, position_m=pos,
                                                      velocity_mps=vel, alive=w.alive, world=w),
            "sensing (relative kind's batch form)": lambda: plant.sensor.batch(ctx, rows),
            "observation batch (BatchHook._observe)": lambda: hook._observe(ctx, rows, hook.ids, lambda: rel),
            "the law (LatticeController.step_batch)": lambda: type(ctrls[0]).step_batch(ctrls, ob),
            "the agents around it (BatchAgents.step)": lambda: hook.agents.step(rows, ob),
            "actuators, dV, HCW step (MissionWorld.step)": lambda: w.step(cmd, sc.step_s, all_alive=True),
        }
        print(f"tersoff-6 batch step {a.at}, each item alone (best of {a.repeats}):")
        for name, f in items.items():
            n = 2000
            us = min(timeit.repeat(f, number=n, repeat=a.repeats)) / n * 1e6
            print(f"  {name:46s} {us:6.2f} us")
        print("  (BatchAgents.step includes step_batch; MissionWorld.step stepped the world on: timed last)")
        run = sc.with_overrides(duration_s=3000.0)
        floor(sc.with_overrides(duration_s=sc.step_s))
        run_in_process(sc.with_overrides(duration_s=sc.step_s), Path(tmp) / "warm", "b", record="truth")
        fl, bl = [], []
        for k in range(a.repeats):
            fl.append(floor(run)["loop_s"])
            bl.append(run_in_process(run, Path(tmp) / f"r{k}", "b", record="truth").summary["loop_wall_s"])
        rec.close()
        print(f"in the run's loop, {run.steps} steps, min of {a.repeats}: batch {min(bl) / run.steps * 1e6:.1f} us a step, "
              f"floor {min(fl) / run.steps * 1e6:.1f} us a step (ratio of the minima {min(bl) / min(fl):.2f})")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
