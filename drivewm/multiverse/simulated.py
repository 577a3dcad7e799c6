"""Branch a simulated scenario: fork its simulator at the branch time, one future per plan
(drivewm.sim.fork_highway, drivewm.sim.fork_sumo); the other road users react to the ego."""

from __future__ import annotations

import math
import os

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.multiverse.branch import Branch
from drivewm.multiverse.config import MultiverseConfig
from drivewm.multiverse.plans import parse_plans
from drivewm.multiverse.scenario import Scenario


def branch_scenario(cfg: MultiverseConfig, scenario: Scenario) -> Branch:
    """Fork the scenario's simulator at its branch time, one future per plan."""
    sim = scenario.sim
    branch_tick = int(round(scenario.at_s * sim.fps))
    future_ticks = int(round(cfg.horizon_s * sim.fps))
    plans = parse_plans(cfg.plans, np.arange(1, future_ticks + 1) / sim.fps, cfg.waypoint_dt_s)
    if sim.source == "highway" and any(plan.turn for plan in plans):
        raise DrivewmError("plans: turns at a junction need a SUMO scenario (grid, spider, random)")
    if sim.source == "highway":
        os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")  # highway-env imports pygame
        from drivewm.sim.fork_highway import fork_highway as fork
    else:
        from drivewm.sim.fork_sumo import fork_sumo as fork
    past, futures, road, infeasible = fork(sim, branch_tick, plans, future_ticks, scenario.placed)
    keep = int(math.floor(cfg.past_s * sim.fps + 1e-9)) + 1
    from drivewm.sim.drives import describe
    from drivewm.sim.paired import drive_id
    from drivewm.sim.scene import SceneRecording
    from drivewm.sim.world import sim_rig

    tags = {"road_type": sim.road_type, "source": "highway-env" if sim.source == "highway" else "sumo"}
    tags.update(weather=sim.weather, time_of_day=sim.time_of_day, traffic_density=sim.traffic_density)
    tags["drive_id"] = drive_id(sim)
    description = describe(sim, SceneRecording(road, past, tags))
    if not past:
        raise DrivewmError("multiverse: the scenario has no ticks before the branch point")
    rig, source = sim_rig(sim), tags["source"]
    return Branch(past[-keep:], futures, plans, road, rig, sim, tags, description, source, True, infeasible)
