"""A branch point and its futures' traffic: the shared past and one list of ticks per plan, from a forked simulator or a
replayed log (drivewm.multiverse.replay)."""

from __future__ import annotations

import dataclasses

from drivewm.geometry import Rig
from drivewm.sim.config import SimConfig
from drivewm.sim.ego_plan import EgoPlan
from drivewm.sim.scene import RoadMap, SceneTick


@dataclasses.dataclass
class Branch:
    """One branch point and its futures (world frame, ego origin under the rear axle)."""

    past: list[SceneTick]
    """Ticks up to and including the branch tick, as the source has them (the last ``past_s`` of them)."""
    futures: list[list[SceneTick]]
    """Per plan, the ticks after the branch point."""
    plans: list[EgoPlan]
    road: RoadMap
    rig: Rig
    """The cameras to render, at the run's image size."""
    sim: SimConfig
    """What the simulator's renderer draws (weather, time of day, seed, urban or highway look)."""
    tags: dict[str, str]
    """Scene tags of every future's log."""
    description: str
    source: str
    """highway-env, sumo, or log (a replayed recording)."""
    reactive: bool
    """Whether the other road users react to the ego (simulators) or are replayed (logs)."""
    infeasible: list[str]
    """Per plan, why the simulator could not carry out its manoeuvre at the branch point ("" where it could;
    a replayed log's open-loop manoeuvres always can)."""
