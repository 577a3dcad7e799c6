"""Views of a rig tiled into one grid video: forward-facing cameras on top, as a driver sees them."""

from __future__ import annotations

import numpy as np
from einops import rearrange

from drivewm.geometry import Rig


def viewing_azimuth_rad(rig: Rig) -> np.ndarray:
    """(V,) azimuth in the ego x-y plane of each camera's optical axis (OpenCV +z), 0 = ego +x, + = left."""
    axes = np.stack([c.T_ego_from_cam[:3, 2] for c in rig.cameras])  # (V, 3) camera z axes in ego
    return np.arctan2(axes[:, 1], axes[:, 0])


def grid_layout(rig: Rig) -> list[list[int]]:
    """View indices per row of the grid video: one row for up to 3 cameras; otherwise the forward-
    facing cameras on top (left to right as a driver sees them) and the others below (as seen looking back)."""
    az = viewing_azimuth_rad(rig)
    order = sorted(range(len(az)), key=lambda i: -az[i])
    if len(az) <= 3:
        return [order]
    front = [i for i in order if abs(az[i]) <= np.pi / 2]
    back = sorted((i for i in range(len(az)) if abs(az[i]) > np.pi / 2), key=lambda i: az[i] % (2 * np.pi))
    return [row for row in (front, back) if row]


def tile_views(videos: np.ndarray, layout: list[list[int]]) -> np.ndarray:
    """uint8 (V, T, H, W, 3) -> (T, rows*H, cols*W, 3), views placed by ``layout`` (black where empty)."""
    v, t, h, w, _ = videos.shape
    cols = max(len(row) for row in layout)
    grid = np.zeros((len(layout), cols, t, h, w, 3), dtype=np.uint8)
    for r, row in enumerate(layout):
        for c, view in enumerate(row):
            grid[r, c] = videos[view]
    return rearrange(grid, "r c t h w x -> t (r h) (c w) x")
