"""The scene-state stream every scenario source produces and the renderer consumes.

World frame: right-handed, z up, metres (docs/DESIGN.md section 3). The ground is the plane z = 0.
A source turns its simulator's state into a :class:`SceneRecording`: one static
:class:`RoadMap` per drive and one :class:`SceneTick` per logged frame.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from drivewm.logs.types import AgentBox, RoadLine

LineType = Literal["solid", "dashed", "none"]


@dataclasses.dataclass
class LaneBoundary:
    """A painted (or unpainted) lane border: ``points_xy`` (N, 2) world metres, and how it is painted."""

    points_xy: np.ndarray
    line_type: LineType


@dataclasses.dataclass
class RoadMap:
    """Static road geometry of a drive, in world metres (z = 0).

    ``lane_centers``: centre lines (N_i, 2) in driving direction; ``lane_widths`` (m) one per lane.
    ``boundaries``: lane borders with their line type. ``road_edges``: the outer borders of the
    paved surface (kerbs). ``surface_polygons``: polygons (N_i, 2) whose union is the paved area
    (lanes and junctions); the renderer rasterises these. ``props``: static roadside objects
    (category building | pole | tree) as oriented boxes, placed by :mod:`drivewm.sim.props`.
    """

    lane_centers: list[np.ndarray]
    lane_widths: list[float]
    boundaries: list[LaneBoundary]
    road_edges: list[np.ndarray]
    surface_polygons: list[np.ndarray]
    props: list[AgentBox] = dataclasses.field(default_factory=list)

    def road_lines(self) -> list[RoadLine]:
        """The road as world polylines (z = 0): lane centres, lane borders with their paint, kerbs, and
        the outlines of the surface polygons (what a log's ``/road`` channel carries)."""
        z = lambda p: np.concatenate([p, np.zeros((len(p), 1))], axis=1)  # noqa: E731  (x, y) -> (x, y, 0)
        lines = [RoadLine("lane_center", z(c)) for c in self.lane_centers]
        lines += [RoadLine("lane_boundary", z(b.points_xy), b.line_type) for b in self.boundaries]
        lines += [RoadLine("road_edge", z(e)) for e in self.road_edges]
        return lines + [RoadLine("road_surface", z(p)) for p in self.surface_polygons if len(p) >= 3]

    def bounds_xy(self) -> tuple[np.ndarray, np.ndarray]:
        """(min_xy, max_xy) of every lane centre line (m)."""
        pts = np.concatenate(self.lane_centers, axis=0)
        return pts.min(axis=0), pts.max(axis=0)


@dataclasses.dataclass
class SceneTick:
    """The world at one logged instant: ego pose (origin on the ground under the rear axle, x
    forward) and the other road users as oriented boxes (the ego itself is not among them)."""

    timestamp_ns: int
    T_world_from_ego: np.ndarray
    agents: list[AgentBox]
    ego_speed_mps: float = 0.0


@dataclasses.dataclass
class SceneRecording:
    """One simulated drive: road map, ticks in time order, scene tags and a description."""

    road: RoadMap
    ticks: list[SceneTick]
    tags: dict[str, str]
    description: str = ""
    step_cpu_s: float = 0.0  # CPU seconds the simulator spent stepping (for benchmarks)

    def ego_xy(self) -> np.ndarray:
        """Ego positions (N, 2) over the drive, world metres."""
        return np.array([t.T_world_from_ego[:2, 3] for t in self.ticks])


def box_from_center(
    track_id: str,
    category: str,
    x: float,
    y: float,
    yaw_rad: float,
    size_lwh: tuple[float, float, float],
    color_rgb: tuple[float, float, float],
) -> AgentBox:
    """An AgentBox standing on the ground (z = 0) with its footprint centre at (x, y)."""
    length, width, height = size_lwh
    return AgentBox(
        track_id, category, np.array([x, y, height / 2]), np.array([length, width, height]), float(yaw_rad), color_rgb
    )


def polyline_normals(points_xy: np.ndarray) -> np.ndarray:
    """Unit left normals (N, 2) of a polyline (N, 2) (left of the direction of travel, z up)."""
    d = np.gradient(points_xy, axis=0)
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    return np.stack([-d[:, 1], d[:, 0]], axis=1)
