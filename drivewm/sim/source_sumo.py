"""SUMO scenario source (libsumo): grid, spider and random networks made on the fly -> SceneRecording.

Nothing needs to exist beforehand: ``netgenerate`` builds the network and ``randomTrips.py``
(shipped with the eclipse-sumo package) the traffic, in a temporary folder, all seeded.
SUMO's ``getAngle`` is in degrees, 0 = north, clockwise, and ``getPosition`` is the front bumper
(docs/DESIGN.md section 9); drivewm's ego origin is on the ground under the rear axle.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import sumo
import sumolib

from drivewm.errors import DrivewmError
from drivewm.geometry import T_from_xyz_yaw
from drivewm.sim.config import SimConfig
from drivewm.sim.ego_plan import LANE_CHANGE_S
from drivewm.sim.road_edges import road_edges_from_boundaries, stable_unit, vehicle_look
from drivewm.sim.scene import LaneBoundary, RoadMap, SceneRecording, SceneTick, box_from_center, polyline_normals


def _import_libsumo():
    """libsumo without its pyarrow warning on stdout. libsumo prints "Warning! pyarrow is installed with
    version ..." at import whenever pyarrow (rerun-sdk's dependency) is not the Arrow it was built
    against; its wheel bundles that Arrow under a mangled name (libsumo.libs/libarrow-<hash>.so), so
    the two never meet, and the lines only broke drivewm simulate's output. Anything else is printed."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        import libsumo
    rest = [line for line in printed.getvalue().splitlines() if "pyarrow" not in line]
    if rest:
        print("\n".join(rest))
    return libsumo


libsumo = _import_libsumo()

REAR_OVERHANG_M = 1.0  # rear bumper to rear axle
WARMUP_S = 40.0  # simulated time before the first logged tick, so the streets already have traffic
TRIP_PERIOD_S = {"low": 2.5, "medium": 1.2, "high": 0.6}  # randomTrips --period: one new trip every P s
NETGENERATE_ARGS = {
    "grid": ["--grid", "--grid.number", "4", "--grid.length", "110", "--default.lanenumber", "2"],
    "spider": [
        "--spider",
        "--spider.arm-number",
        "6",
        "--spider.circle-number",
        "3",
        "--spider.space-radius",
        "70",
        "--default.lanenumber",
        "2",
    ],
    "random": [
        "--rand",
        "--rand.iterations",
        "40",
        "--rand.min-distance",
        "70",
        "--rand.max-distance",
        "160",
        "--default.lanenumber",
        "2",
    ],
}


def sumo_tools_dir() -> Path:
    """The ``tools`` folder of the eclipse-sumo package (randomTrips.py lives there)."""
    return Path(sumo.__file__).resolve().parent / "tools"


def _run(cmd: list[str], what: str) -> None:
    env = {**os.environ, "SUMO_HOME": str(Path(sumo.__file__).resolve().parent)}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise DrivewmError(f"SUMO {what} failed: {(proc.stderr or proc.stdout).strip().splitlines()[-1:]}")


def generate_network(scenario: str, seed: int, traffic_density: str, end_s: float, folder: Path) -> tuple[Path, Path]:
    """netgenerate + randomTrips into ``folder``: (net.xml, routes.xml)."""
    net, routes = folder / "net.net.xml", folder / "routes.rou.xml"
    _run(
        [
            sumolib.checkBinary("netgenerate"),
            *NETGENERATE_ARGS[scenario],
            "--seed",
            str(seed),
            "--junctions.corner-detail",
            "5",
            "--no-turnarounds",
            "true",
            "-o",
            str(net),
        ],
        "netgenerate",
    )
    _run(
        [
            sys.executable,
            str(sumo_tools_dir() / "randomTrips.py"),
            "-n",
            str(net),
            "-o",
            str(folder / "trips.xml"),
            "-r",
            str(routes),
            "-e",
            str(int(end_s)),
            "-p",
            str(TRIP_PERIOD_S[traffic_density]),
            "--seed",
            str(seed),
            "--fringe-factor",
            "3",
            "--min-distance",
            "100",
            "--validate",
        ],
        "randomTrips",
    )
    return net, routes


def record_sumo(cfg: SimConfig) -> SceneRecording:
    """Run one SUMO drive (network and traffic generated in a temp dir) and return its scene stream."""
    dt = 1.0 / cfg.fps
    with tempfile.TemporaryDirectory(prefix="drivewm-sumo-") as tmp:
        net_path, routes = generate_network(
            cfg.scenario, cfg.seed, cfg.traffic_density, WARMUP_S + cfg.duration_s + 60, Path(tmp)
        )
        start_sumo(net_path, routes, dt, cfg.seed)
        try:
            ticks, step_cpu_s = _drive(libsumo, cfg, dt)
        finally:
            libsumo.close()
        xy = np.array([t.T_world_from_ego[:2, 3] for t in ticks])
        road = road_map_from_net(net_path, xy.min(axis=0) - cfg.max_range_m, xy.max(axis=0) + cfg.max_range_m)
    return SceneRecording(road, ticks, {"road_type": cfg.road_type, "source": "sumo"}, step_cpu_s=step_cpu_s)


def start_sumo(net_path: Path, routes: Path, dt: float, seed: int, extra: tuple[str, ...] = ()) -> None:
    """Start libsumo on the network and routes (``extra``: more sumo options)."""
    libsumo.start(
        [
            "sumo",
            "-n",
            str(net_path),
            "-r",
            str(routes),
            "--step-length",
            f"{dt}",
            "--seed",
            str(seed),
            "--no-step-log",
            "true",
            "--no-warnings",
            "true",
            "--collision.action",
            "none",
            # SUMO's default lane change moves a vehicle to the next lane within one step (3.2 m sideways in
            # 0.1 s on camera); the simple continuous model spreads it over the given seconds.
            "--lanechange.duration",
            f"{LANE_CHANGE_S}",
            *extra,
        ]
    )


def _drive(traci, cfg: SimConfig, dt: float) -> tuple[list[SceneTick], float]:
    """Warm up, insert the ego, then log one tick per step: (ticks, CPU seconds in simulationStep)."""
    for _ in range(int(WARMUP_S / dt)):
        traci.simulationStep()
    _add_ego(traci, cfg.seed)
    ticks, step_cpu_s = [], 0.0
    for i in range(cfg.simulated_ticks):
        _extend_route(traci, cfg.seed, i)
        ticks.append(_tick(traci, int(round(i * 1e9 / cfg.fps)), cfg.seed))
        t0 = time.process_time()
        traci.simulationStep()
        step_cpu_s += time.process_time() - t0
    return ticks, step_cpu_s


def _drivable_edges(traci) -> list[str]:
    return sorted(e for e in traci.edge.getIDList() if not e.startswith(":"))


def _add_ego(traci, seed: int) -> None:
    """Insert the ego on a seeded random edge with a far destination; step until it is on the road."""
    edges = _drivable_edges(traci)
    for attempt in range(50):
        a = edges[int(stable_unit(seed, "ego-from", attempt) * len(edges))]
        b = edges[int(stable_unit(seed, "ego-to", attempt) * len(edges))]
        route = traci.simulation.findRoute(a, b).edges
        if len(route) >= 3:
            break
    else:
        raise DrivewmError(f"SUMO network (seed {seed}): found no route for the ego")
    traci.route.add("ego_route", list(route))
    traci.vehicle.add("ego", "ego_route", depart="now", departLane="best", departSpeed="max")
    for _ in range(200):
        traci.simulationStep()
        if "ego" in traci.vehicle.getIDList():
            return
    raise DrivewmError(f"SUMO network (seed {seed}): the ego could not be inserted")


def _extend_route(traci, seed: int, tick: int) -> None:
    """Give the ego a new far destination before it reaches its last edge, so it never leaves."""
    route = traci.vehicle.getRoute("ego")
    if len(route) - traci.vehicle.getRouteIndex("ego") > 2:
        return
    edges = _drivable_edges(traci)
    for attempt in range(20):
        target = edges[int(stable_unit(seed, "ego-next", tick, attempt) * len(edges))]
        try:
            traci.vehicle.changeTarget("ego", target)
        except Exception:  # libsumo raises its own TraCIException when no route exists
            continue
        if len(traci.vehicle.getRoute("ego")) - traci.vehicle.getRouteIndex("ego") > 2:
            return


def _tick(traci, timestamp_ns: int, seed: int) -> SceneTick:
    agents = []
    ego_T = None
    for vid in traci.vehicle.getIDList():
        fx, fy = traci.vehicle.getPosition(vid)
        yaw = math.radians(90.0 - traci.vehicle.getAngle(vid))
        length = traci.vehicle.getLength(vid)
        d = np.array([math.cos(yaw), math.sin(yaw)])
        if vid == "ego":
            rear = np.array([fx, fy]) - (length - REAR_OVERHANG_M) * d
            ego_T = T_from_xyz_yaw(rear[0], rear[1], 0.0, yaw)
            speed = traci.vehicle.getSpeed(vid)
            continue
        c = np.array([fx, fy]) - 0.5 * length * d
        category, height, color = vehicle_look(seed, vid)
        agents.append(
            box_from_center(vid, category, c[0], c[1], yaw, (length, traci.vehicle.getWidth(vid), height), color)
        )
    if ego_T is None:
        raise DrivewmError("SUMO: the ego vehicle left the simulation")
    return SceneTick(timestamp_ns, ego_T, agents, float(speed))


def road_map_from_net(net_path: Path, lo_xy: np.ndarray, hi_xy: np.ndarray) -> RoadMap:
    """Lanes, painted borders, junction areas of a SUMO net (sumolib) inside the world box."""
    net = sumolib.net.readNet(str(net_path), withInternal=True)
    centers, widths, boundaries, polygons = [], [], [], []
    for edge in net.getEdges(withInternal=True):
        internal = edge.getFunction() == "internal"
        lanes = edge.getLanes()
        for i, lane in enumerate(lanes):
            pts = _densify(np.array(lane.getShape(), dtype=np.float64)[:, :2])
            if len(pts) < 2 or not np.any(np.all((pts >= lo_xy) & (pts <= hi_xy), axis=1)):
                continue
            w = lane.getWidth()
            n = polyline_normals(pts)
            right, left = pts - 0.5 * w * n, pts + 0.5 * w * n
            polygons.append(np.concatenate([right, left[::-1]], axis=0))
            if internal:
                continue
            centers.append(pts)
            widths.append(float(w))
            boundaries.append(LaneBoundary(right, "solid" if i == 0 else "dashed"))
            if i == len(lanes) - 1:
                boundaries.append(LaneBoundary(left, "solid"))
    for node in net.getNodes():
        shape = np.array(node.getShape(), dtype=np.float64)
        if len(shape) >= 3:
            polygons.append(shape[:, :2])
    edges = road_edges_from_boundaries(boundaries, polygons)
    return RoadMap(centers, widths, boundaries, edges, polygons)


def _densify(points_xy: np.ndarray, step_m: float = 1.0) -> np.ndarray:
    """Resample a polyline so consecutive points are at most ``step_m`` apart."""
    out = [points_xy[:1]]
    for a, b in zip(points_xy[:-1], points_xy[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step_m)))
        out.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    pts = np.concatenate(out, axis=0)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-6])
    return pts[keep]
