"""Shared road-map helpers: which lane borders are road edges, vehicle colours and heights."""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING

import numpy as np

from drivewm.sim.scene import LaneBoundary, polyline_normals

if TYPE_CHECKING:
    from matplotlib.path import Path as MplPath

#: Body colours (RGB in [0, 1]) of simulated vehicles: the common real-world car colours.
CAR_PALETTE = (
    (0.92, 0.92, 0.92),
    (0.08, 0.08, 0.09),
    (0.55, 0.56, 0.58),
    (0.72, 0.73, 0.75),
    (0.62, 0.08, 0.07),
    (0.10, 0.20, 0.50),
    (0.15, 0.35, 0.20),
    (0.85, 0.65, 0.10),
    (0.45, 0.30, 0.18),
    (0.20, 0.45, 0.70),
)
#: (category, height m, probability): what a simulated 2D vehicle becomes in 3D.
BODY_TYPES = (("car", 1.48, 0.72), ("car", 1.70, 0.18), ("van", 2.05, 0.10))


def stable_unit(*keys: object) -> float:
    """A deterministic number in [0, 1) from keys (not Python's salted hash)."""
    digest = hashlib.blake2b("/".join(map(str, keys)).encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") / 2**64


def vehicle_look(seed: int, track_id: str) -> tuple[str, float, tuple[float, float, float]]:
    """(category, height m, colour) of a vehicle, fixed by the drive seed and its track id."""
    u = stable_unit(seed, track_id, "body")
    acc = 0.0
    for body in BODY_TYPES:
        acc += body[2]
        if u < acc:
            break
    category, height, _ = body
    color = CAR_PALETTE[int(stable_unit(seed, track_id, "color") * len(CAR_PALETTE))]
    return category, height, color


def road_edges_from_boundaries(
    boundaries: list[LaneBoundary], surface_polygons: list[np.ndarray], probe_m: float = 0.6
) -> list[np.ndarray]:
    """Lane borders with paved surface on one side only: the kerbs.

    A border is an edge where points ``probe_m`` to one side lie off every surface polygon.
    """
    from matplotlib.path import Path as MplPath  # here: ~0.3 s of import that every CLI command would pay

    paths = [MplPath(p) for p in surface_polygons if len(p) >= 3]
    edges = []
    for b in boundaries:
        if len(b.points_xy) < 2:
            continue
        n = polyline_normals(b.points_xy)
        left = _on_surface(paths, b.points_xy + probe_m * n)
        right = _on_surface(paths, b.points_xy - probe_m * n)
        if np.mean(left ^ right) > 0.5:
            edges.append(b.points_xy)
    return edges


def _on_surface(paths: list[MplPath], points_xy: np.ndarray) -> np.ndarray:
    inside = np.zeros(len(points_xy), dtype=bool)
    for p in paths:
        inside |= p.contains_points(points_xy)
    return inside
