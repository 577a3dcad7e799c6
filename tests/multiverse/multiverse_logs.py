"""A small recorded-style drive log: a straight two-lane road, the ego at 10 m/s, a parked car ahead in
its lane and a car passing in the other lane (front1 rig at 64x32)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drivewm.geometry import T_from_xyz_yaw, load_rig
from drivewm.logs.types import AgentBox, RoadLine, SceneInfo
from drivewm.logs.writer import LogWriter

T0_NS = 1_700_000_000_000_000_000
TICKS = 40  # 4 s at 10 Hz
EGO_SPEED_MPS = 10.0
PARKED_X_M = 45.0


def log_agents(k: int) -> list[AgentBox]:
    parked = AgentBox(
        "parked", "car", np.array([PARKED_X_M, -1.75, 0.8]), np.array([4.6, 1.9, 1.6]), 0.0, (0.8, 0.1, 0.1)
    )
    passing = AgentBox(
        "passing", "car", np.array([5.0 + 14.0 * k / 10, 1.75, 0.8]), np.array([4.6, 1.9, 1.6]), 0.0, (0.1, 0.1, 0.8)
    )
    return [parked, passing]


def write_test_log(path: Path, poses: bool = True, agents: bool = True) -> Path:
    """The drive as an MCAP log; without ``poses`` or ``agents`` those channels are left out."""
    rig = load_rig("front1").scaled(64, 32, fit="stretch")
    x = np.linspace(-50.0, 150.0, 41)
    line = lambda y: np.stack([x, np.full_like(x, y), np.zeros_like(x)], axis=1)  # noqa: E731
    road = [
        RoadLine("lane_center", line(-1.75)),
        RoadLine("lane_center", line(1.75)),
        RoadLine("lane_boundary", line(0.0), "dashed"),
    ]
    road += [RoadLine("road_edge", line(-3.5)), RoadLine("road_edge", line(3.5))]
    road += [RoadLine("road_surface", np.concatenate([line(-3.5), line(3.5)[::-1]]))]
    scene = SceneInfo(
        {"weather": "clear", "time_of_day": "day", "road_type": "highway", "source": "fleet"}, "a test drive"
    )
    with LogWriter(path, rig, scene) as writer:
        writer.write_road(T0_NS, road)
        for k in range(TICKS):
            t = T0_NS + k * 100_000_000
            writer.write_images(t, {"CAM_FRONT": np.full((32, 64, 3), 90 + k, np.uint8)})
            if poses:
                writer.write_pose(t, T_from_xyz_yaw(EGO_SPEED_MPS * k / 10, -1.75, 0.0, 0.0))
            if agents:
                writer.write_agents(t, log_agents(k))
    return path
