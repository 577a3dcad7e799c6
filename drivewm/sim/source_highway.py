"""highway-env scenario source: highway, merge, roundabout, intersection -> SceneRecording.

highway-env is 2D with its y axis pointing down in its own render (docs/DESIGN.md section 9), so a
z-up world is X = x, Y = -y, yaw = -heading. Its vehicle position is the box centre; the ego
origin is on the ground under the rear axle. The ego is an IDM + MOBIL driver (car following and
lane changes, Treiber 2000 / Kesting 2007), so drives are sensible without a trained policy; it
holds the brake at a standstill, as does the intersection's traffic (:class:`HoldingIDMVehicle`).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Iterator

import highway_env.envs as envs
import numpy as np
from highway_env.vehicle.behavior import IDMVehicle

from drivewm.geometry import T_from_xyz_yaw
from drivewm.sim.config import SimConfig
from drivewm.sim.road_edges import road_edges_from_boundaries, vehicle_look
from drivewm.sim.scene import LaneBoundary, RoadMap, SceneRecording, SceneTick, box_from_center

#: Distance from the vehicle centre back to the rear axle (m) for a 5 m highway-env car.
REAR_AXLE_BEHIND_CENTER_M = 1.5
#: Simulator sub-steps are at most this long (s); highway-env's own default is 1/15 s.
MAX_SUBSTEP_S = 1.0 / 15.0
LINE_TYPES = {0: "none", 1: "dashed", 2: "solid", 3: "solid"}
DENSITY = {"low": (15, 0.7), "medium": (30, 1.0), "high": (50, 1.6)}  # (vehicles_count, vehicles_density)
#: IDMVehicle class constants that highway-env's IntersectionEnv overwrites on its traffic's class
#: (IDMVehicle, or here HoldingIDMVehicle) when it places its vehicles (DISTANCE_WANTED = 7,
#: COMFORT_ACC_MAX = 6, COMFORT_ACC_MIN = -3): left so, every later drive in the same process would
#: follow other traffic rules than in a fresh one.
IDM_CLASS_CONSTANTS = {
    name: vars(IDMVehicle)[name] for name in ("DISTANCE_WANTED", "COMFORT_ACC_MAX", "COMFORT_ACC_MIN")
}


def make_env(scenario: str, traffic_density: str, seed: int):
    """The unwrapped highway-env environment for ``scenario``, reset with ``seed``."""
    count, density = DENSITY[traffic_density]
    classes = {
        "highway": envs.HighwayEnv,
        "merge": envs.MergeEnv,
        "roundabout": envs.RoundaboutEnv,
        "intersection": envs.IntersectionEnv,
    }
    config = {"vehicles_count": count, "vehicles_density": density} if scenario == "highway" else {}
    if scenario == "intersection":
        config = {
            "initial_vehicle_count": count // 3,
            "spawn_probability": min(0.3 * density, 0.9),
            "other_vehicles_type": f"{__name__}.HoldingIDMVehicle",
        }
    env = classes[scenario](config=config)
    env.reset(seed=seed)
    return env


def record_highway(cfg: SimConfig) -> SceneRecording:
    """Run one highway-env drive and return its scene-state stream.

    A drive whose ego crashes is rerun with the next simulator seed (up to 5 tries), since a
    crashed ego stands still for the rest of the drive.
    """
    with idm_class_constants():
        for attempt in range(5):
            rec = _run_once(cfg, cfg.seed * 7919 + attempt)
            if rec is not None:
                return rec
        return _run_once(cfg, cfg.seed * 7919 + 5, allow_crash=True)


@contextlib.contextmanager
def idm_class_constants() -> Iterator[None]:
    """Start from highway-env's own IDM constants and put them back afterwards, so a drive's traffic
    does not depend on which scenarios ran before it in the process (see IDM_CLASS_CONSTANTS)."""
    _reset_idm_class_constants()
    try:
        yield
    finally:
        _reset_idm_class_constants()


def _reset_idm_class_constants() -> None:
    for name, value in IDM_CLASS_CONSTANTS.items():
        setattr(IDMVehicle, name, value)
        if name in vars(HoldingIDMVehicle):  # the intersection sets them on its traffic's class: ours
            delattr(HoldingIDMVehicle, name)


class HoldingIDMVehicle(IDMVehicle):
    """highway-env's IDM + MOBIL driver that never backs up: the ego of every scenario and the
    intersection's traffic. IDM's braking term still pulls at a standstill when the gap ahead is
    short, and highway-env lets speeds go negative (MIN_SPEED -40): its ego rolled backwards in 9 of
    the worldmodel recipe's 15 intersection drives, for up to 6 s and at up to 2 m/s, and up to 2 %
    of the other cars' ticks there backed up. A driver waiting at a junction holds the brake
    instead, so each step's deceleration stops at zero speed."""

    def step(self, dt: float) -> None:
        self.action["acceleration"] = max(float(self.action["acceleration"]), -self.speed / dt)
        super().step(dt)


class HighwayDrive:
    """A highway-env drive being stepped: the environment, its ego and the track ids handed out so far.
    :func:`record_highway` runs one to the end; drivewm.sim.fork_highway copies one at a branch point."""

    def __init__(self, cfg: SimConfig, sim_seed: int):
        self.cfg = cfg
        self.env = make_env(cfg.scenario, cfg.traffic_density, sim_seed)
        old = self.env.vehicle
        self.ego = HoldingIDMVehicle.create_from(old)
        self.env.road.vehicles[self.env.road.vehicles.index(old)] = self.ego
        self.env.controlled_vehicles = [self.ego]
        self.substeps = max(1, math.ceil((1.0 / cfg.fps) / MAX_SUBSTEP_S))
        self.dt = 1.0 / cfg.fps / self.substeps
        # id(vehicle) -> (vehicle, track id): holding every vehicle keeps its id() from going to a later one (the
        # intersection removes cars that left and spawns new ones, which CPython may place at a freed address)
        self.ids: dict[int, tuple[object, str]] = {}

    def tick(self, i: int) -> SceneTick:
        """The scene at logged tick ``i`` (the simulator's present state)."""
        return _tick(self.env, self.ego, int(round(i * 1e9 / self.cfg.fps)), self.ids, self.cfg.seed)

    def step(self) -> float:
        """Advance the traffic by one logged tick; returns the CPU seconds it took."""
        t0 = time.process_time()
        for _ in range(self.substeps):
            self.env.road.act()
            self.env.road.step(self.dt)
        if self.cfg.scenario == "intersection":
            self.env._clear_vehicles()
            self.env._spawn_vehicle(spawn_probability=self.env.config["spawn_probability"])
        return time.process_time() - t0

    def road_map(self, ticks: list[SceneTick]) -> RoadMap:
        """The road network around the ego's path over ``ticks``."""
        xy = np.array([t.T_world_from_ego[:2, 3] for t in ticks])
        lo, hi = xy.min(axis=0) - self.cfg.max_range_m, xy.max(axis=0) + self.cfg.max_range_m
        return road_map_from_network(self.env.road.network, lo, hi)


def _run_once(cfg: SimConfig, sim_seed: int, allow_crash: bool = False) -> SceneRecording | None:
    drive = HighwayDrive(cfg, sim_seed)
    ticks = []
    step_cpu_s = 0.0
    for i in range(cfg.simulated_ticks):
        ticks.append(drive.tick(i))
        step_cpu_s += drive.step()
        if drive.ego.crashed and not allow_crash:
            return None
    drive.env.close()
    road = drive.road_map(ticks)
    tags = {"road_type": cfg.road_type, "source": "highway-env"}
    return SceneRecording(road, ticks, tags, step_cpu_s=step_cpu_s)


def _tick(env, ego, timestamp_ns: int, ids: dict[int, tuple[object, str]], seed: int) -> SceneTick:
    yaw = -float(ego.heading)
    cx, cy = float(ego.position[0]), -float(ego.position[1])
    rear_x = cx - REAR_AXLE_BEHIND_CENTER_M * math.cos(yaw)
    rear_y = cy - REAR_AXLE_BEHIND_CENTER_M * math.sin(yaw)
    agents = []
    for v in env.road.vehicles:
        if v is ego:
            continue
        track_id = ids.setdefault(id(v), (v, f"veh{len(ids):03d}"))[1]
        category, height, color = vehicle_look(seed, track_id)
        agents.append(
            box_from_center(
                track_id,
                category,
                float(v.position[0]),
                -float(v.position[1]),
                -float(v.heading),
                (float(v.LENGTH), float(v.WIDTH), height),
                color,
            )
        )
    return SceneTick(timestamp_ns, T_from_xyz_yaw(rear_x, rear_y, 0.0, yaw), agents, float(ego.speed))


def road_map_from_network(network, lo_xy: np.ndarray, hi_xy: np.ndarray, step_m: float = 1.0) -> RoadMap:
    """Sample the lanes of a highway-env RoadNetwork inside the world box [lo_xy, hi_xy] into
    world-frame polylines (z up). (highway-env's straight roads are 10 km long.)"""
    centers, widths, boundaries, polygons = [], [], [], []
    for lanes in (ls for d in network.graph.values() for ls in d.values()):
        for lane in lanes:
            s = _stations_inside(lane, lo_xy, hi_xy, step_m)
            if s is None:
                continue
            w = np.array([lane.width_at(x) for x in s])
            sides = []
            for sign in (-1.0, 0.0, 1.0):
                pts = np.array([lane.position(x, sign * wi / 2) for x, wi in zip(s, w)])
                sides.append(pts * np.array([1.0, -1.0]))
            centers.append(sides[1])
            widths.append(float(w.mean()))
            boundaries.append(LaneBoundary(sides[0], LINE_TYPES[int(lane.line_types[0])]))
            boundaries.append(LaneBoundary(sides[2], LINE_TYPES[int(lane.line_types[1])]))
            polygons.append(np.concatenate([sides[0], sides[2][::-1]], axis=0))
    edges = road_edges_from_boundaries(boundaries, polygons)
    return RoadMap(centers, widths, boundaries, edges, polygons)


def _stations_inside(lane, lo_xy: np.ndarray, hi_xy: np.ndarray, step_m: float, coarse_m: float = 10.0):
    """Arc lengths (every ``step_m``) of the part of ``lane`` inside the world box, or None."""
    s = np.linspace(0.0, lane.length, max(2, int(math.ceil(lane.length / coarse_m)) + 1))
    xy = np.array([lane.position(x, 0.0) for x in s]) * np.array([1.0, -1.0])
    inside = np.all((xy >= lo_xy) & (xy <= hi_xy), axis=1)
    if not inside.any():
        return None
    idx = np.flatnonzero(inside)
    s0, s1 = s[max(idx[0] - 1, 0)], s[min(idx[-1] + 1, len(s) - 1)]
    return np.linspace(s0, s1, max(2, int(math.ceil((s1 - s0) / step_m)) + 1))
