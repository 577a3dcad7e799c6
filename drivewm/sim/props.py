"""Static roadside objects placed from the road map: street lamps, trees and buildings.

Everything is placed along the road edges (kerbs) at seeded random spacings, off the paved
surface and not overlapping, so the scene has vertical structure to see and to match. Props
are AgentBox records with category pole | lamp | trunk | crown | building.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from drivewm.logs.types import AgentBox
from drivewm.sim.scene import RoadMap, box_from_center, polyline_normals

GRID_M = 0.5  # occupancy grid resolution used to keep props off the road and apart
LAMP_SPACING_M = 32.0
LAMP_HEIGHT_M = 7.5


class _Occupancy:
    """Coarse boolean grid of what is taken (road surface, placed props)."""

    def __init__(self, road: RoadMap, lo_xy: np.ndarray, hi_xy: np.ndarray):
        self.origin = lo_xy
        shape = (int((hi_xy[1] - lo_xy[1]) / GRID_M) + 2, int((hi_xy[0] - lo_xy[0]) / GRID_M) + 2)
        self.grid = np.zeros(shape, np.uint8)
        cv2.fillPoly(self.grid, [self._px(p) for p in road.surface_polygons if len(p) >= 3], 1)
        self.grid = cv2.dilate(self.grid, np.ones((3, 3), np.uint8))  # keep 0.5 m off the kerb

    def _px(self, pts: np.ndarray) -> np.ndarray:
        return np.round((pts - self.origin) / GRID_M).astype(np.int32)

    def free(self, footprint_xy: np.ndarray) -> bool:
        mask = np.zeros_like(self.grid)
        cv2.fillConvexPoly(mask, self._px(footprint_xy), 1)
        inside = mask.sum() > 0 and np.all(
            (footprint_xy >= self.origin)
            & (footprint_xy < self.origin + GRID_M * np.array(self.grid.shape[::-1]) - GRID_M)
        )
        return bool(inside) and not np.any(self.grid & mask)

    def take(self, footprint_xy: np.ndarray) -> None:
        cv2.fillConvexPoly(self.grid, self._px(footprint_xy), 1)


def _footprint(x: float, y: float, yaw: float, length: float, width: float, margin: float = 0.5) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = length / 2 + margin, width / 2 + margin
    corners = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    return corners @ np.array([[c, s], [-s, c]]) + [x, y]


def place_props(road: RoadMap, lo_xy: np.ndarray, hi_xy: np.ndarray, seed: int, urban: bool) -> list[AgentBox]:
    """Lamps, then buildings, then trees along every road edge, seeded and non-overlapping."""
    rng = np.random.default_rng([seed, 202])
    occ = _Occupancy(road, lo_xy, hi_xy)
    props: list[AgentBox] = []
    sides = [_outward_samples(e, occ) for e in road.road_edges if len(e) >= 2]
    for pts, out in sides:
        _place_lamps(pts, out, occ, props, rng)
    for pts, out in sides:
        _place_buildings(pts, out, occ, props, rng, urban)
    for pts, out in sides:
        _place_trees(pts, out, occ, props, rng, urban)
    return props


def _outward_samples(edge_xy: np.ndarray, occ: _Occupancy) -> tuple[np.ndarray, np.ndarray]:
    """Edge points and unit normals pointing away from the road (the side the grid shows free)."""
    n = polyline_normals(edge_xy)
    probe = occ._px(edge_xy + 1.5 * n)
    probe = np.clip(probe, 0, np.array(occ.grid.shape[::-1]) - 1)
    left_on_road = occ.grid[probe[:, 1], probe[:, 0]].mean() > 0.5
    return edge_xy, (-n if left_on_road else n)


def _walk(pts: np.ndarray, spacing: float, rng: np.random.Generator, jitter: float):
    """Indices along a 1 m-sampled polyline every ~``spacing`` metres (seeded jitter)."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    pos = rng.uniform(0, spacing)
    while pos < s[-1]:
        yield int(np.searchsorted(s, pos).clip(0, len(pts) - 1))
        pos += spacing * (1 + rng.uniform(-jitter, jitter))


def _place_lamps(pts, out, occ, props, rng) -> None:
    for i in _walk(pts, LAMP_SPACING_M, rng, 0.05):
        p = pts[i] + 1.6 * out[i]
        yaw = math.atan2(-out[i][1], -out[i][0])  # the arm points over the road
        fp = _footprint(p[0], p[1], yaw, 0.3, 0.3, 0.2)
        if not occ.free(fp):
            continue
        occ.take(fp)
        k = len(props)
        props.append(
            box_from_center(f"pole{k}", "pole", p[0], p[1], yaw, (0.22, 0.22, LAMP_HEIGHT_M), (0.45, 0.46, 0.48))
        )
        head = p - 1.3 * out[i]
        lamp = box_from_center(f"lamp{k}", "lamp", head[0], head[1], yaw, (1.8, 0.45, 0.25), (0.35, 0.35, 0.37))
        lamp.center_xyz[2] = LAMP_HEIGHT_M - 0.1
        props.append(lamp)


def _place_buildings(pts, out, occ, props, rng, urban: bool) -> None:
    spacing = 14.0 if urban else 55.0
    for i in _walk(pts, spacing, rng, 0.4):
        length, depth = rng.uniform(8, 22), rng.uniform(8, 16)
        height = rng.uniform(6, 22) if urban else rng.uniform(5, 10)
        setback = (4.5 if urban else 14.0) + rng.uniform(0, 4 if urban else 25)
        p = pts[i] + (setback + depth / 2) * out[i]
        yaw = math.atan2(out[i][1], out[i][0]) + math.pi / 2  # long side faces the road
        fp = _footprint(p[0], p[1], yaw, length, depth, 0.8)
        if not occ.free(fp):
            continue
        occ.take(fp)
        color = _building_color(rng)
        props.append(box_from_center(f"bldg{len(props)}", "building", p[0], p[1], yaw, (length, depth, height), color))


def _building_color(rng: np.random.Generator) -> tuple[float, float, float]:
    palette = (
        (0.72, 0.66, 0.58),
        (0.62, 0.38, 0.30),
        (0.80, 0.78, 0.72),
        (0.55, 0.57, 0.60),
        (0.78, 0.70, 0.52),
        (0.45, 0.42, 0.40),
    )
    return palette[int(rng.integers(len(palette)))]


def _place_trees(pts, out, occ, props, rng, urban: bool) -> None:
    for i in _walk(pts, 10.0 if urban else 16.0, rng, 0.5):
        off = rng.uniform(2.0, 3.0) if urban else rng.uniform(5.0, 14.0)
        p = pts[i] + off * out[i]
        crown_w, height = rng.uniform(2.2, 4.0), rng.uniform(5.0, 9.0)
        fp = _footprint(p[0], p[1], 0.0, crown_w, crown_w, 0.3)
        if not occ.free(fp):
            continue
        occ.take(fp)
        k = len(props)
        yaw = rng.uniform(0, math.pi / 2)
        trunk_h = height * 0.4
        props.append(box_from_center(f"trunk{k}", "trunk", p[0], p[1], yaw, (0.35, 0.35, trunk_h), (0.33, 0.24, 0.16)))
        crown = box_from_center(
            f"crown{k}",
            "crown",
            p[0],
            p[1],
            yaw,
            (crown_w, crown_w, height - trunk_h),
            (0.20, 0.36 + 0.1 * rng.uniform(), 0.14),
        )
        crown.center_xyz[2] = trunk_h + (height - trunk_h) / 2
        props.append(crown)
