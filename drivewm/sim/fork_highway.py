"""Fork a highway-env drive at a branch point: every future starts from one deep copy of the simulation.

The past (ticks 0 .. branch) is the drive :func:`drivewm.sim.source_highway.record_highway` makes with
the same config (the same attempt seed: a drive whose ego crashed is rerun with the next seed, judged
on the past alone). At the branch the ego's IDM + MOBIL driver hands over to the plan: a
:class:`PlanVehicle` (highway-env's lane-following steering, the plan's acceleration) or a
:class:`PosesVehicle` (placed along given poses); every other road user keeps its own driver and
reacts (IDM car following, MOBIL lane changes; Treiber 2000, Kesting 2007).
"""

from __future__ import annotations

import copy
import math

import numpy as np
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from drivewm.errors import DrivewmError
from drivewm.geometry import T_from_xyz_yaw
from drivewm.sim.config import SimConfig
from drivewm.sim.ego_plan import EgoPlan, PlacedVehicle, no_lane_reason
from drivewm.sim.scene import RoadMap, SceneTick
from drivewm.sim.source_highway import (
    REAR_AXLE_BEHIND_CENTER_M,
    HighwayDrive,
    HoldingIDMVehicle,
    idm_class_constants,
)

ATTEMPTS = 5  # as record_highway


class PlanVehicle(ControlledVehicle):
    """The ego under a manoeuvre plan: highway-env's steering controller towards the target lane, and the
    plan's acceleration (no car following: a plan that drives into a car collides with it). It never backs up."""

    plan_accel_mps2: float = 0.0
    plan_max_speed_mps: float = 33.0

    def act(self, action=None) -> None:
        if self.crashed:
            return
        self.follow_road()
        cap = max(self.plan_max_speed_mps, self.speed)
        accel = self.plan_accel_mps2 if self.speed < cap or self.plan_accel_mps2 < 0 else 0.0
        Vehicle.act(self, {"steering": self.steering_control(self.target_lane_index), "acceleration": accel})

    def step(self, dt: float) -> None:
        self.action["acceleration"] = max(float(self.action.get("acceleration", 0.0)), -self.speed / dt)
        super().step(dt)


class PosesVehicle(Vehicle):
    """The ego placed along given centre positions and headings (highway-env's frame), one per logged tick,
    moved linearly between them over the simulator's sub-steps."""

    def __init__(self, road, centers_xy: np.ndarray, headings: np.ndarray, substeps: int, tick_s: float):
        super().__init__(road, centers_xy[0], float(headings[0]), 0.0)
        self.centers_xy, self.headings = centers_xy, headings
        self.substeps, self.tick_s, self.k = substeps, tick_s, 0

    def act(self, action=None) -> None:
        pass

    def step(self, dt: float) -> None:
        self.k += 1
        i, frac = divmod(self.k, self.substeps)
        i = min(i, len(self.centers_xy) - 2)
        frac = 1.0 if self.k >= (len(self.centers_xy) - 1) * self.substeps else frac / self.substeps
        a, b = self.centers_xy[i], self.centers_xy[i + 1]
        self.position = a + frac * (b - a)
        self.heading = float(self.headings[i] + frac * _wrap(self.headings[i + 1] - self.headings[i]))
        self.speed = float(np.linalg.norm(b - a) / self.tick_s)
        self.on_state_update()


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def fork_highway(
    cfg: SimConfig, branch_tick: int, plans: list[EgoPlan], future_ticks: int, placed: list[PlacedVehicle] = ()
) -> tuple[list[SceneTick], list[list[SceneTick]], RoadMap, list[str]]:
    """(past ticks 0 .. branch_tick, one list of ``future_ticks`` ticks per plan, the road around them all,
    per plan why its manoeuvre cannot be carried out at the branch point, "" where it can)."""
    with idm_class_constants():
        drive, past = _past(cfg, branch_tick)
        futures, infeasible = zip(*[_future(drive, branch_tick, plan, future_ticks, placed) for plan in plans])
        road = drive.road_map(past + [t for f in futures for t in f])
        drive.env.close()
    return past, list(futures), road, list(infeasible)


def _past(cfg: SimConfig, branch_tick: int) -> tuple[HighwayDrive, list[SceneTick]]:
    """The drive at the branch point and its ticks so far, with record_highway's choice of attempt seed."""
    for attempt in range(ATTEMPTS + 1):
        drive = HighwayDrive(cfg, cfg.seed * 7919 + attempt)
        past, crashed = [], False
        for i in range(branch_tick + 1):
            past.append(drive.tick(i))
            at_branch = copy.deepcopy(drive) if i == branch_tick else None
            drive.step()
            crashed = crashed or drive.ego.crashed
            if crashed and attempt < ATTEMPTS:
                break
        if not crashed or attempt == ATTEMPTS:
            drive.env.close()
            return at_branch, past
    raise AssertionError("unreachable")


def _future(
    at_branch: HighwayDrive, branch_tick: int, plan: EgoPlan, future_ticks: int, placed: list[PlacedVehicle]
) -> tuple[list[SceneTick], str]:
    """The future's ticks and why its plan is infeasible ("" where it is not)."""
    drive = copy.deepcopy(at_branch)
    drive.ids = {id(v): (v, track) for v, track in drive.ids.values()}  # the copies' identities
    infeasible = _hand_over(drive, plan, future_ticks)
    for k, p in enumerate(placed):
        _place(drive, p, f"placed{k}")
    ticks = []
    for k in range(1, future_ticks + 1):
        drive.step()
        ticks.append(drive.tick(branch_tick + k))
    drive.env.close()
    return ticks, infeasible


def _hand_over(drive: HighwayDrive, plan: EgoPlan, future_ticks: int) -> str:
    """Replace the ego's driver by the plan's; why the plan's lane change cannot be made ("": it can, or
    there is none). The ego of an infeasible lane change keeps its lane."""
    old, infeasible = drive.ego, ""
    if plan.turn:
        raise DrivewmError(f"plan {plan.name!r}: turns at a junction need a SUMO scenario")
    if plan.is_kinematic:
        ego = _poses_vehicle(drive, old, plan, future_ticks)
    else:
        ego = PlanVehicle.create_from(old)
        ego.plan_accel_mps2, ego.plan_max_speed_mps = plan.accel_mps2, plan.max_speed_mps
        _from, _to, lane = old.lane_index
        target = lane - plan.lane_change  # highway-env numbers lanes from the left
        if not 0 <= target < len(drive.env.road.network.graph[_from][_to]):
            infeasible, target = no_lane_reason(plan.lane_change), lane
        ego.target_lane_index = (_from, _to, target)
    drive.env.road.vehicles[drive.env.road.vehicles.index(old)] = ego
    drive.env.controlled_vehicles = [ego]
    drive.ego = ego
    return infeasible


def _poses_vehicle(drive: HighwayDrive, old, plan: EgoPlan, future_ticks: int) -> PosesVehicle:
    yaw0 = -float(old.heading)
    c0 = np.array([old.position[0], -old.position[1]])
    T_world_from_branch = T_from_xyz_yaw(
        *(c0 - REAR_AXLE_BEHIND_CENTER_M * np.array([math.cos(yaw0), math.sin(yaw0)])), 0.0, yaw0
    )
    T = np.concatenate([T_world_from_branch[None], T_world_from_branch @ plan.T_branch_from_ego[:future_ticks]])
    yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    centers = T[:, :2, 3] + REAR_AXLE_BEHIND_CENTER_M * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    return PosesVehicle(drive.env.road, centers * np.array([1.0, -1.0]), -yaw, drive.substeps, 1.0 / drive.cfg.fps)


def _place(drive: HighwayDrive, p: PlacedVehicle, track_id: str) -> None:
    road, ego = drive.env.road, drive.ego
    lane_index = road.network.get_closest_lane_index(ego.position, ego.heading)
    lane = road.network.get_lane(lane_index)
    s = lane.local_coordinates(ego.position)[0] + p.gap_m
    position, heading = lane.position(s, 0.0), lane.heading_at(s)
    speed = float(ego.speed if p.speed_mps is None else p.speed_mps)
    if speed == 0.0:
        vehicle = Vehicle(road, position, heading, 0.0)
    else:
        vehicle = HoldingIDMVehicle(road, position, heading, speed, lane_index, speed)
    road.vehicles.append(vehicle)
    drive.ids[id(vehicle)] = (vehicle, track_id)  # named as in SUMO's futures
