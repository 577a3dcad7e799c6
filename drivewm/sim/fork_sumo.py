"""Fork a SUMO drive at a branch point: libsumo saves the simulation state there
(``simulation.saveState``, random number generators included) and every future starts by loading it
into a fresh SUMO (``simulation.loadState``; sumo.dlr.de/docs/Simulation/SaveAndLoad.html).

The past (ticks 0 .. branch) is the drive :func:`drivewm.sim.source_sumo.record_sumo` makes with the
same config (same network, traffic and ego). After the branch the ego follows the plan with SUMO's
safety checks off (speed mode 0: a plan that drives into a car collides with it; ``--collision.action
none`` keeps both on the road), while every other vehicle keeps SUMO's car following (Krauss) and
lane changing and reacts to it.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.sim.config import SimConfig
from drivewm.sim.ego_plan import LANE_CHANGE_S, EgoPlan, PlacedVehicle, no_lane_reason, speed_profile
from drivewm.sim.scene import RoadMap, SceneTick
from drivewm.sim.source_sumo import (
    REAR_OVERHANG_M,
    WARMUP_S,
    _add_ego,
    _extend_route,
    _tick,
    generate_network,
    libsumo,
    road_map_from_net,
    start_sumo,
)

#: State files keep every digit (SUMO's default is 2 decimals) and the random number generators.
STATE_OPTIONS = ("--save-state.rng", "true", "--save-state.precision", "17", "--route-steps", "0")
#: SUMO lane change mode: strategic changes (to stay on the route) unless a TraCI request says otherwise;
#: no cooperative, speed-gain or keep-right changes of its own.
EGO_LANE_CHANGE_MODE = 0b01
PLACED_LENGTH_M = 5.0
EGO_INSERTION_DECEL_MPS2 = 100.0
#: Braking for a turn ahead (m/s^2), how many junctions ahead that looks, and the acceleration back to the
#: plan's speed after one (m/s^2; a plan's own acceleration where it is higher).
JUNCTION_DECEL_MPS2 = 3.0
JUNCTIONS_AHEAD = 2
RESUME_ACCEL_MPS2 = 2.0
#: SUMO link directions of each turn plan, in order of preference.
TURN_DIRECTIONS = {"left": (("l", "L"),), "right": (("r", "R"),), "any": (("l", "L"), ("r", "R"))}


def fork_sumo(
    cfg: SimConfig, branch_tick: int, plans: list[EgoPlan], future_ticks: int, placed: list[PlacedVehicle] = ()
) -> tuple[list[SceneTick], list[list[SceneTick]], RoadMap, list[str]]:
    """(past ticks 0 .. branch_tick, one list of ``future_ticks`` ticks per plan, the road around them all,
    per plan why its manoeuvre cannot be carried out at the branch point, "" where it can)."""
    dt = 1.0 / cfg.fps
    with tempfile.TemporaryDirectory(prefix="drivewm-fork-") as tmp:
        net, routes = generate_network(
            cfg.scenario, cfg.seed, cfg.traffic_density, WARMUP_S + cfg.duration_s + 60, Path(tmp)
        )
        start_sumo(net, routes, dt, cfg.seed, STATE_OPTIONS)
        try:
            past = _past(cfg, dt, branch_tick)
            state = str(Path(tmp) / "branch.xml")
            libsumo.simulation.saveState(state)
            results = []
            for i, plan in enumerate(plans):
                # A fresh SUMO for every future: loadState into the simulation that ran the previous future
                # leaves some of its state behind (the ego froze on the lane that future ended on, its speed set
                # but its position no longer advanced, after a lane change or turn brought it there again).
                libsumo.close()
                start_sumo(net, routes, dt, cfg.seed, STATE_OPTIONS)
                results.append(_future(cfg, state, branch_tick, i, plan, future_ticks, placed))
            futures, infeasible = zip(*results)
        finally:
            libsumo.close()
        xy = np.array([t.T_world_from_ego[:2, 3] for t in past + [t for f in futures for t in f]])
        road = road_map_from_net(net, xy.min(axis=0) - cfg.max_range_m, xy.max(axis=0) + cfg.max_range_m)
    return past, list(futures), road, list(infeasible)


def _past(cfg: SimConfig, dt: float, branch_tick: int) -> list[SceneTick]:
    """record_sumo's drive up to the branch tick, stopped before its step."""
    for _ in range(int(WARMUP_S / dt)):
        libsumo.simulationStep()
    _add_ego(libsumo, cfg.seed)
    past = []
    for i in range(branch_tick + 1):
        _extend_route(libsumo, cfg.seed, i)
        past.append(_tick(libsumo, int(round(i * 1e9 / cfg.fps)), cfg.seed))
        if i < branch_tick:
            libsumo.simulationStep()
    return past


def _future(
    cfg: SimConfig, state: str, branch_tick: int, index: int, plan: EgoPlan, future_ticks: int, placed
) -> tuple[list[SceneTick], str]:
    """The future's ticks and why its plan is infeasible ("" where it is not)."""
    libsumo.simulation.loadState(state)
    v0 = libsumo.vehicle.getSpeed("ego")
    infeasible = _hand_over(plan)
    for k, p in enumerate(placed):
        _place(p, k, index, v0)
    times = np.arange(1, future_ticks + 1) / cfg.fps
    speeds = speed_profile(v0, plan.accel_mps2, plan.max_speed_mps, times)
    poses = _front_poses(plan, future_ticks) if plan.is_kinematic else None
    ticks, v = [], v0
    for k in range(future_ticks):
        if poses is None:
            v = min(float(speeds[k]), _junction_speed_cap(), v + max(plan.accel_mps2, RESUME_ACCEL_MPS2) / cfg.fps)
            libsumo.vehicle.setSpeed("ego", v)
        else:
            x, y, angle_deg = poses[k]
            libsumo.vehicle.moveToXY("ego", "", -1, x, y, angle_deg, keepRoute=2)
        libsumo.simulationStep()
        if poses is None:
            _extend_route(libsumo, cfg.seed, branch_tick + 1 + k)
        ticks.append(_tick(libsumo, int(round((branch_tick + 1 + k) * 1e9 / cfg.fps)), cfg.seed))
    return ticks, infeasible


def _junction_speed_cap() -> float:
    """The fastest the ego may drive now (m/s) to take the turns ahead on its route at their speed: netconvert
    gives each turn through a junction a speed limit from its radius (``--junctions.limit-turn-speed``, 5.5 m/s^2
    of lateral acceleration), and a driver brakes for it at :data:`JUNCTION_DECEL_MPS2` (v^2 = v_turn^2 + 2 b d).
    The plan's own speed holds everywhere else: speed mode 0 ignores every limit."""
    lane = libsumo.vehicle.getLaneID("ego")
    cap = libsumo.lane.getMaxSpeed(lane) if lane.startswith(":") else math.inf  # inside a junction: its turn
    distance = libsumo.lane.getLength(lane) - libsumo.vehicle.getLanePosition("ego")
    for link in libsumo.vehicle.getNextLinks("ego")[:JUNCTIONS_AHEAD]:
        # (to lane, priority, open, foe, via lane, state, direction, length through the junction)
        via, length = link[4], link[7]
        if via:
            cap = min(cap, math.sqrt(libsumo.lane.getMaxSpeed(via) ** 2 + 2 * JUNCTION_DECEL_MPS2 * distance))
        distance += length + libsumo.lane.getLength(link[0])
    return cap


def _hand_over(plan: EgoPlan) -> str:
    """The ego drops SUMO's safety checks and takes the plan's lane change and turn; why it cannot ("" where
    it can: the ego of an infeasible plan keeps its lane and route)."""
    libsumo.vehicle.setSpeedMode("ego", 0)
    # The plan sets the ego's speed itself; SUMO's braking limits then only serve insertion checks, which
    # would refuse a placed vehicle (drivewm.sim.ego_plan.PlacedVehicle) the ego could not stop for.
    libsumo.vehicle.setDecel("ego", EGO_INSERTION_DECEL_MPS2)
    libsumo.vehicle.setEmergencyDecel("ego", EGO_INSERTION_DECEL_MPS2)
    libsumo.vehicle.setLaneChangeMode("ego", EGO_LANE_CHANGE_MODE)
    infeasible = _change_lane(plan.lane_change) if plan.lane_change else ""
    if plan.turn:
        infeasible = infeasible or _take_turn(plan.turn)
    return infeasible


def _change_lane(lane_change: int) -> str:
    """Ask SUMO for the lane change (over :data:`LANE_CHANGE_S`); why there is none to make ("": asked)."""
    edge = libsumo.vehicle.getRoadID("ego")
    if edge.startswith(":"):
        return "the ego is inside a junction at the branch point"
    target = libsumo.vehicle.getLaneIndex("ego") + lane_change  # SUMO numbers lanes from the right
    if not 0 <= target < libsumo.edge.getLaneNumber(edge):
        return no_lane_reason(lane_change)
    _route_from_lane(edge, f"{edge}_{target}")
    libsumo.vehicle.changeLane("ego", target, LANE_CHANGE_S)
    return ""


def _route_from_lane(edge: str, lane: str) -> None:
    """Route the ego on from ``lane`` where its route's next edge cannot be reached from there (straight on
    where it can): otherwise SUMO stops it at the end of the lane it was sent to, holding it there for the
    lane change's duration, and its strategic lane change then takes it back."""
    route, idx = libsumo.vehicle.getRoute("ego"), libsumo.vehicle.getRouteIndex("ego")
    links = libsumo.lane.getLinks(lane)  # (to lane, priority, open, foe, via, state, direction, length)
    reachable = [libsumo.lane.getEdgeID(link[0]) for link in links]
    if not links or (idx + 1 < len(route) and route[idx + 1] in reachable):
        return
    straight = [e for e, link in zip(reachable, links) if link[6] == "s"]
    _route_via([edge], (straight or reachable)[0])


def _route_via(edges: list[str], following: str) -> None:
    """Route the ego along ``edges`` (from the one it is on), then ``following``, then on to its destination.
    The route must reach well past ``following``: on a shorter one, drivewm.sim.source_sumo._extend_route's
    ``changeTarget`` routes the ego afresh from the edge it is on, which undoes the turn or the lane's exit."""
    destination = libsumo.vehicle.getRoute("ego")[-1]
    onward = libsumo.simulation.findRoute(following, destination).edges if following != destination else ()
    libsumo.vehicle.setRoute("ego", [*edges, *(onward or [following])])


def _take_turn(side: str) -> str:
    """Route the ego through a ``side`` turn (left, right, or any: left if there is one) at its next junction;
    why it cannot ("": routed)."""
    route, idx = libsumo.vehicle.getRoute("ego"), libsumo.vehicle.getRouteIndex("ego")
    for directions in TURN_DIRECTIONS[side]:
        for start in (idx, idx + 1):  # the edge it is on, or the next one when it is inside a junction
            if start >= len(route):
                break
            edge = route[start]
            own = libsumo.vehicle.getLaneIndex("ego") if start == idx else 0  # its own lane's turns first
            lanes = sorted(range(libsumo.edge.getLaneNumber(edge)), key=lambda lane: lane != own)
            for lane in lanes:
                for link in libsumo.lane.getLinks(f"{edge}_{lane}"):
                    if link[6] in directions:  # (to lane, priority, open, foe, via, state, direction, length)
                        _route_via(list(route[idx : start + 1]), libsumo.lane.getEdgeID(link[0]))
                        return ""
    return f"the ego's next junction has no {'left or right' if side == 'any' else side} turn"


def _front_poses(plan: EgoPlan, future_ticks: int) -> np.ndarray:
    """(N, 3) front bumper x, y (m) and SUMO angle (degrees, 0 = north, clockwise) of a waypoint plan."""
    yaw0 = math.radians(90.0 - libsumo.vehicle.getAngle("ego"))
    length = libsumo.vehicle.getLength("ego")
    front = np.array(libsumo.vehicle.getPosition("ego"))
    d0 = np.array([math.cos(yaw0), math.sin(yaw0)])
    rear = front - (length - REAR_OVERHANG_M) * d0
    c, s = math.cos(yaw0), math.sin(yaw0)
    T = plan.T_branch_from_ego[:future_ticks]
    yaw = yaw0 + np.arctan2(T[:, 1, 0], T[:, 0, 0])
    xy = rear + T[:, :2, 3] @ np.array([[c, s], [-s, c]])
    xy = xy + (length - REAR_OVERHANG_M) * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    return np.concatenate([xy, (90.0 - np.degrees(yaw))[:, None] % 360.0], axis=1)


def _place(p: PlacedVehicle, k: int, future: int, ego_speed_mps: float) -> None:
    """Add a vehicle on the ego's lane, ``p.gap_m`` centre to centre from the ego, inserted at the next step."""
    lane = libsumo.vehicle.getLaneID("ego")
    if lane.startswith(":"):
        raise DrivewmError("placed vehicles: the ego is inside a junction at the branch point; pick another time")
    edge = libsumo.lane.getEdgeID(lane)
    ego_center = libsumo.vehicle.getLanePosition("ego") - 0.5 * libsumo.vehicle.getLength("ego")
    front = ego_center + p.gap_m + 0.5 * PLACED_LENGTH_M
    if not PLACED_LENGTH_M <= front <= libsumo.lane.getLength(lane):
        raise DrivewmError(f"placed vehicle at {p.gap_m:+g} m: off the ego's lane {lane}; pick another time")
    route = libsumo.vehicle.getRoute("ego")
    rest = list(route[route.index(edge) :]) if edge in route else [edge]
    route_id = f"placed{k}_route_f{future}"  # route ids outlive loadState; vehicles do not
    libsumo.route.add(route_id, rest)
    speed = ego_speed_mps if p.speed_mps is None else p.speed_mps
    vid = f"placed{k}"
    libsumo.vehicle.add(
        vid,
        route_id,
        depart="now",
        departLane=str(libsumo.vehicle.getLaneIndex("ego")),
        departPos=f"{front:.3f}",
        departSpeed=f"{speed:.3f}",
    )
    libsumo.vehicle.setLength(vid, PLACED_LENGTH_M)
    if speed == 0.0:
        libsumo.vehicle.setSpeed(vid, 0.0)
