"""Overlap blending: the first frame of every generated view made to agree where cameras overlap.

Reprojected refinement (drivewm.multiview.reproject) warps each view's own first frame along the
trajectory, so where two cameras overlap each keeps what its own first pass drew, and the two need
not show the same road or scenery: the eval's cross-view matches (CSE) fail there. Before the
warp, every view's first frame is blended across the rig as a panorama is: each pixel's ray is
followed into the warp's flat world (the road, the corridor's walls, or infinity:
:func:`drivewm.multiview.warp.flat_world_points`), looked up in every camera that sees that point,
and the colours are averaged, each camera weighted by the point's distance to its image border
(feathering, Szeliski 2006, "Image alignment and stitching", section 6.2). A camera's edge thus
fades into its neighbour, and two cameras that see the same point get the same colour for it.
Road and distant scenery are exact; what stands closer than infinity above the road is doubled
by its parallax, as in any flat-world panorama.

It is for generated first frames only: a real clip's frames already agree, and blending them
would double their roadside (generate with ``--condition-clip`` and rollouts leave them as they are).
Measured: docs/quality-vs-compute.md, "Cameras that disagree where they overlap".
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from drivewm.geometry import Rig
from drivewm.multiview.warp import check_corridor, flat_world_points, source_pixels


def blend_overlaps(frames: np.ndarray, rig: Rig, max_ground_m: float = 100.0, walls_m: float = 0.0) -> np.ndarray:
    """uint8 (V, H, W, 3) first frames of ``rig`` (rig order) -> the same, each pixel the feathered
    mean of every camera that sees its flat-world point, its own camera among them. A pixel no
    other camera sees keeps its colour; ``max_ground_m`` and ``walls_m`` as in
    :func:`drivewm.multiview.warp.warp_grid`."""
    check_corridor(rig, walls_m)
    images = view_tensor(frames, rig)
    _, h, w, _ = frames.shape
    out = np.empty(frames.shape, dtype=np.float64)
    for v, cam in enumerate(rig.cameras):
        ground, point, d = flat_world_points(cam, (h, w), np.eye(4), max_ground_m, walls_m)
        total, weights = np.zeros((h * w, 3)), np.zeros(h * w)
        for s, src in enumerate(rig.cameras):
            x, y = source_pixels(src, (h, w), ground, point, d)
            with np.errstate(invalid="ignore"):  # NaN: behind camera s
                border = np.minimum(np.minimum(x + 0.5, w - 0.5 - x), np.minimum(y + 0.5, h - 0.5 - y))
            weight = np.where(border > 0, border, 0.0)  # px to the nearest image border, 0 outside
            if weight.any():
                total += weight[:, None] * sample_view(images, s, x, y)
                weights += weight
        own = frames[v].reshape(-1, 3).astype(np.float64)
        seen = weights > 0
        out[v] = np.where(seen[:, None], total / np.where(seen, weights, 1.0)[:, None], own).reshape(h, w, 3)
    return out.round().clip(0, 255).astype(np.uint8)


def overlap_disagreement(frames: np.ndarray, rig: Rig, max_ground_m: float = 100.0, walls_m: float = 0.0) -> float:
    """Mean absolute colour difference (8-bit levels) between a pixel of one view and where another
    camera sees its flat-world point, over every such pair of ``frames`` (uint8 (V, H, W, 3), rig
    order) at least one pixel inside the other image: 0 for views that agree wherever they overlap
    (up to bilinear sampling and what parallax moves); NaN where no two cameras overlap."""
    images = view_tensor(frames, rig)
    _, h, w, _ = frames.shape
    total, count = 0.0, 0
    for v, cam in enumerate(rig.cameras):
        ground, point, d = flat_world_points(cam, (h, w), np.eye(4), max_ground_m, walls_m)
        own = frames[v].reshape(-1, 3).astype(np.float64)
        for s, src in enumerate(rig.cameras):
            if s == v:
                continue
            x, y = source_pixels(src, (h, w), ground, point, d)
            with np.errstate(invalid="ignore"):
                inside = (x >= 0.5) & (x <= w - 1.5) & (y >= 0.5) & (y <= h - 1.5)
            if inside.any():
                total += float(np.abs(own[inside] - sample_view(images, s, x[inside], y[inside])).sum())
                count += int(inside.sum()) * 3
    return total / count if count else float("nan")


def view_tensor(frames: np.ndarray, rig: Rig) -> torch.Tensor:
    """uint8 (V, H, W, 3) views of ``rig`` -> float (V, 3, H, W) for :func:`sample_view`."""
    if len(frames) != len(rig.cameras):
        raise ValueError(f"{len(frames)} views for a rig of {len(rig.cameras)} cameras")
    return torch.from_numpy(np.ascontiguousarray(frames)).float().permute(0, 3, 1, 2)


def sample_view(images: torch.Tensor, s: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Colours (N, 3) of view ``s`` of :func:`view_tensor`'s ``images`` at pixel coordinates ``x``, ``y``
    (N,), bilinear, clamped to the image (NaN read as 0: weigh them out)."""
    h, w = images.shape[2:]
    grid = np.stack([(np.nan_to_num(x) + 0.5) / w * 2 - 1, (np.nan_to_num(y) + 0.5) / h * 2 - 1], axis=1)
    grid = torch.from_numpy(grid).float().view(1, 1, -1, 2)
    colour = F.grid_sample(images[s : s + 1], grid, mode="bilinear", padding_mode="border", align_corners=False)
    return colour[0, :, 0].T.double().numpy()
