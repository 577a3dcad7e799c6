"""Oriented boxes on the ground plane: corners, overlap (separating axis theorem) and distance."""

from __future__ import annotations

import numpy as np


def box_corners(center_xy: np.ndarray, yaw_rad: float, length_m: float, width_m: float) -> np.ndarray:
    """(4, 2) corners of an oriented rectangle, counter-clockwise."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * np.array([length_m / 2, width_m / 2])
    return center_xy + half @ np.array([[c, s], [-s, c]])


def boxes_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two convex quadrilaterals (4, 2) overlap: no edge normal of either separates them (SAT)."""
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1)
        pa, pb = a @ normals.T, b @ normals.T
        if np.any((pa.max(axis=0) < pb.min(axis=0)) | (pb.max(axis=0) < pa.min(axis=0))):
            return False
    return True


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (P, S) from points p (P, 2) to segments a -> b (S, 2)."""
    ab = b - a
    t = np.clip(((p[:, None] - a[None]) * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12)[None], 0, 1)
    return np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1)


def box_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Shortest distance (m) between two convex quadrilaterals, 0 when they overlap."""
    if boxes_overlap(a, b):
        return 0.0
    d1 = _point_segment_distance(a, b, np.roll(b, -1, axis=0)).min()
    d2 = _point_segment_distance(b, a, np.roll(a, -1, axis=0)).min()
    return float(min(d1, d2))


def polyline_distance(points_xy: np.ndarray, lines: list[np.ndarray]) -> np.ndarray:
    """(P,) distance from each point to the nearest of the polylines (inf with none)."""
    segs = [(line[:-1], line[1:]) for line in lines if len(line) >= 2]
    if not segs:
        return np.full(len(points_xy), np.inf)
    a = np.concatenate([s[0] for s in segs])
    b = np.concatenate([s[1] for s in segs])
    return _point_segment_distance(np.asarray(points_xy, dtype=np.float64), a, b).min(axis=1)
