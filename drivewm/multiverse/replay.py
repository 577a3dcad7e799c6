"""Branch a recorded drive: its road users are replayed from their logged boxes (non-reactive, as
nuPlan's open-loop mode), the ego is placed along each plan's poses from its pose at the branch point.

Manoeuvres are driven open-loop in the branch point's ego frame (drivewm.sim.ego_plan.manoeuvre_poses:
straight ahead, a lane change as a smoothstep); turns need a simulator's road graph and are refused.
The futures' ticks are the log's own pose times after the branch point, up to the horizon or the log's end.
"""

from __future__ import annotations

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.logs.reader import read_log
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS, DriveLog
from drivewm.multiverse.branch import Branch
from drivewm.multiverse.config import MultiverseConfig
from drivewm.multiverse.plans import parse_plans
from drivewm.multiverse.scenario import conditions_from_prompt
from drivewm.sim.config import SimConfig
from drivewm.sim.ego_plan import EgoPlan, manoeuvre_poses
from drivewm.sim.scene import LaneBoundary, RoadMap, SceneTick

#: Lane width given to a log's lane centre lines (the /road channel carries no widths).
LOG_LANE_WIDTH_M = 3.5


def branch_log(cfg: MultiverseConfig) -> Branch:
    """The log's past up to ``cfg.at_s`` and one replayed future per plan."""
    log = read_log(cfg.log, require_images=False)
    _check_log(log)
    ts = log.pose_timestamps_ns
    at_ns = int(ts[0]) + int(round(cfg.at_s * 1e9))
    if not cfg.at_s >= 0 or at_ns > int(ts[-2]):
        span = (ts[-1] - ts[0]) / 1e9
        raise DrivewmError(
            f"{cfg.log}: branch time {cfg.at_s:g} s is outside the log (0 .. {span:g} s with a future after it)"
        )
    b = int(np.searchsorted(ts, at_ns, side="right")) - 1
    end = int(np.searchsorted(ts, ts[b] + int(round(cfg.horizon_s * 1e9)), side="right"))
    first = int(np.searchsorted(ts, ts[b] - int(round(cfg.past_s * 1e9)), side="left"))
    future_times_s = (ts[b + 1 : end] - ts[b]) / 1e9
    plans = parse_plans(cfg.plans, future_times_s, cfg.waypoint_dt_s)
    agents = _agents_at(log, ts)
    speeds = _speeds(log)
    past = [SceneTick(int(ts[i]), log.T_world_from_ego[i], agents[i], speeds[i]) for i in range(first, b + 1)]
    futures = [_future(log, plan, b, end, agents, speeds[b]) for plan in plans]
    sim = _render_config(log, cfg)
    rig = log.rig.scaled(cfg.width, cfg.height, fit="stretch")
    tags = {**log.scene.tags, "weather": sim.weather, "time_of_day": sim.time_of_day}
    road, infeasible = road_from_log(log), [""] * len(plans)
    return Branch(past, futures, plans, road, rig, sim, tags, log.scene.description, "log", False, infeasible)


def _check_log(log: DriveLog) -> None:
    if len(log.pose_timestamps_ns) < 2:
        raise DrivewmError(f"{log.path}: the log has no ego poses to branch from")
    if not any(boxes for _, boxes in log.agents):
        raise DrivewmError(f"{log.path}: the log has no road users (/agents) to replay")


def _agents_at(log: DriveLog, times_ns: np.ndarray) -> list[list]:
    """The road users at each time: the last /agents message at or before it (none before the first)."""
    stamps = np.array([t for t, _ in log.agents], dtype=np.int64)
    idx = np.searchsorted(stamps, times_ns, side="right") - 1
    return [list(log.agents[i][1]) if i >= 0 else [] for i in idx]


def _speeds(log: DriveLog) -> np.ndarray:
    """Ego speed (m/s) at each pose from the displacement to the next (the last repeats the one before)."""
    xy = log.T_world_from_ego[:, :2, 3]
    dt = np.diff(log.pose_timestamps_ns) / 1e9
    v = np.linalg.norm(np.diff(xy, axis=0), axis=1) / np.maximum(dt, 1e-9)
    return np.concatenate([v, v[-1:]])


def _future(log: DriveLog, plan: EgoPlan, b: int, end: int, agents: list, v0_mps: float) -> list[SceneTick]:
    if plan.turn:
        raise DrivewmError(f"plan {plan.name!r}: turns at a junction need a SUMO scenario, not a recorded log")
    ts = log.pose_timestamps_ns
    times_s = (ts[b + 1 : end] - ts[b]) / 1e9
    T_rel = plan.T_branch_from_ego if plan.is_kinematic else manoeuvre_poses(plan, v0_mps, times_s)
    T_world = log.T_world_from_ego[b] @ T_rel
    xy = np.concatenate([log.T_world_from_ego[b][None, :2, 3], T_world[:, :2, 3]])
    speeds = np.linalg.norm(np.diff(xy, axis=0), axis=1) / np.maximum(np.diff(ts[b:end]) / 1e9, 1e-9)
    return [SceneTick(int(ts[b + 1 + k]), T_world[k], agents[b + 1 + k], float(speeds[k])) for k in range(len(times_s))]


def _render_config(log: DriveLog, cfg: MultiverseConfig) -> SimConfig:
    """What the simulator's renderer draws for the log: its tagged conditions, the prompt's where it names them."""
    tags = log.scene.tags
    fields = {
        "weather": tags.get("weather") if tags.get("weather") in WEATHERS else "clear",
        "time_of_day": tags.get("time_of_day") if tags.get("time_of_day") in TIMES_OF_DAY else "day",
        "source": "sumo" if tags.get("source") == "sumo" else "highway",
        "width": cfg.width,
        "height": cfg.height,
        "seed": cfg.seed,
    }
    return SimConfig(**{**fields, **conditions_from_prompt(cfg.prompt)})


def road_from_log(log: DriveLog) -> RoadMap:
    """A RoadMap from the log's /road polylines (lane centres, painted borders, kerbs, paved outlines)."""
    kinds: dict[str, list] = {"lane_center": [], "lane_boundary": [], "road_edge": [], "road_surface": []}
    for line in log.road:
        if line.kind in kinds:
            kinds[line.kind].append(line)
    centers = [np.asarray(line.points_xyz)[:, :2] for line in kinds["lane_center"]]
    boundaries = [
        LaneBoundary(np.asarray(line.points_xyz)[:, :2], line.line_type or "none") for line in kinds["lane_boundary"]
    ]
    edges = [np.asarray(line.points_xyz)[:, :2] for line in kinds["road_edge"]]
    polygons = [np.asarray(line.points_xyz)[:, :2] for line in kinds["road_surface"]]
    return RoadMap(centers, [LOG_LANE_WIDTH_M] * len(centers), boundaries, edges, polygons)
