"""Overlap blending: generated views made to agree where cameras overlap, the first frame before the
reprojection and every frame after it.

Reprojected refinement (drivewm.generate.reproject) warps each view's own first frame along the
trajectory, so where two cameras overlap each keeps what its own first pass drew, and the two need
not show the same road or scenery: the eval's cross-view matches (CSE) fail there. Before the
warp, every view's first frame is blended across the rig as a panorama is: each pixel's ray is
followed into the warp's flat world (the road or infinity:
:func:`drivewm.views.warp.flat_world_points`), looked up in every camera that sees that point,
and the colours are averaged, each camera weighted by the point's distance to its image border
(feathering, Szeliski 2006, "Image alignment and stitching", section 6.2). A camera's edge thus
fades into its neighbour, and two cameras that see the same point get the same colour for it.
Road and distant scenery are exact; what stands closer than infinity above the road is doubled
by its parallax, as in any flat-world panorama.

The refinement then redraws each view on its own, so :func:`stitch_views` (the ``stitch`` post-step)
blends every decoded frame the same way. Neither is for a real clip's frames: those
agree already, and blending them would double their roadside (generate with ``--condition-clip``
and rollouts leave them as they are; a transfer keeps its source's geometry and is not stitched,
but shares its look through the same :func:`feathering`, drivewm.transfer.detail.share_look).
Figures with and without the blend: docs/results.md.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from drivewm.geometry import Rig
from drivewm.views.warp import flat_world_points, source_pixels


def blend_overlaps(frames: np.ndarray, rig: Rig, max_ground_m: float = 100.0) -> np.ndarray:
    """uint8 (V, H, W, 3) first frames of ``rig`` (rig order) -> the same, each pixel the feathered
    mean of every camera that sees its flat-world point, its own camera among them. A pixel no
    other camera sees keeps its colour; ``max_ground_m`` as in
    :func:`drivewm.views.warp.warp_grid`."""
    return stitch_views(frames[:, None], rig, max_ground_m)[:, 0]


def stitch_views(videos: np.ndarray, rig: Rig, max_ground_m: float = 100.0) -> np.ndarray:
    """uint8 (V, T, H, W, 3) generated views of ``rig`` (rig order) -> the same, every frame blended
    as :func:`blend_overlaps` blends one (the ``stitch`` post-step): all cameras of a frame are
    exposed from one ego pose, so the flat world and the feathering weights are the same in every
    frame and are computed once."""
    check_views(videos, rig)
    plan = feathering(rig, videos.shape[2:4], max_ground_m)
    return feathered_mean(videos, plan).round().clip(0, 255).astype(np.uint8)


def feathering(rig: Rig, grid_hw: tuple[int, int], max_ground_m: float = 100.0) -> list:
    """How :func:`feathered_mean` blends views of ``rig`` of ``grid_hw`` (H, W): per view, in rig
    order, one term per camera that sees some of its pixels' flat-world points, (camera, those
    pixels' flat indices, where that camera sees them (x, y), their weights: px to its nearest image
    border). Computed once for any number of frames and channels."""
    h, w = grid_hw
    plan = []
    for seen_from in lookups(rig, (h, w), max_ground_m):
        terms = []
        for s, (x, y) in enumerate(seen_from):
            with np.errstate(invalid="ignore"):  # NaN: behind camera s
                border = np.minimum(np.minimum(x + 0.5, w - 0.5 - x), np.minimum(y + 0.5, h - 0.5 - y))
            seen = np.flatnonzero(np.where(border > 0, border, 0.0))
            if seen.size:
                terms.append((s, seen, x[seen], y[seen], border[seen]))
        plan.append(terms)
    return plan


def feathered_mean(
    values: np.ndarray, plan: list, guide: np.ndarray | None = None, tolerance: float | None = None
) -> np.ndarray:
    """float64 (V, T, H, W, C) of ``values`` (V, T, H, W, C, any dtype; views of a :func:`feathering`
    plan's rig and size): each pixel the feathered mean of every camera that sees its flat-world point,
    its own camera among them; a pixel no camera sees keeps its value. ``guide`` (V, T, H, W, C'):
    another camera counts at a point only as far as the guide agrees there with the view's own,
    weight times exp(-(d / ``tolerance``)^2), d the mean absolute difference of the guide's channels
    (where the guide differs, the two cameras do not see one surface of the flat world); a guide needs
    its tolerance (levels of the guide's scale, > 0)."""
    if guide is not None and not (tolerance is not None and tolerance > 0):
        raise ValueError(f"feathered_mean: a guide needs a tolerance > 0, got {tolerance}")
    _, t, h, w, c = values.shape
    out = np.empty(values.shape, dtype=np.float64)
    for v, terms in enumerate(plan):
        total, weights = np.zeros((t, h * w, c)), np.zeros((t, h * w))
        mine = None if guide is None else guide[v].reshape(t, h * w, -1).astype(np.float64)
        for s, seen, x, y, weight in terms:
            wt = np.broadcast_to(weight, (t, len(weight)))
            if mine is not None and s != v:
                d = np.abs(mine[:, seen] - sample_frames(guide[s], x, y)).mean(-1)
                wt = wt * np.exp(-((d / tolerance) ** 2))
            total[:, seen] += wt[..., None] * sample_frames(values[s], x, y)
            weights[:, seen] += wt
        own = values[v].reshape(t, -1, c).astype(np.float64)
        seen = weights > 0
        mean = total / np.where(seen, weights, 1.0)[..., None]
        out[v] = np.where(seen[..., None], mean, own).reshape(t, h, w, c)
    return out


def overlap_disagreement(frames: np.ndarray, rig: Rig, max_ground_m: float = 100.0) -> float:
    """Mean absolute colour difference (8-bit levels) between a pixel of one view and where another
    camera sees its flat-world point, over every such pair of ``frames`` (uint8 (V, H, W, 3), rig
    order; or (V, T, H, W, 3): pooled over the T frames, the geometry computed once) at least one
    pixel inside the other image: 0 for views that agree wherever they overlap (up to bilinear
    sampling and what parallax moves); NaN where no two cameras overlap."""
    check_views(frames, rig)
    videos = frames if frames.ndim == 5 else frames[:, None]
    h, w = videos.shape[2:4]
    total, count = 0.0, 0
    for v, seen_from in enumerate(lookups(rig, (h, w), max_ground_m)):
        own = videos[v].reshape(len(videos[v]), -1, 3).astype(np.float64)
        for s, (x, y) in enumerate(seen_from):
            if s == v:
                continue
            with np.errstate(invalid="ignore"):
                inside = (x >= 0.5) & (x <= w - 1.5) & (y >= 0.5) & (y <= h - 1.5)
            if inside.any():
                total += float(np.abs(own[:, inside] - sample_frames(videos[s], x[inside], y[inside])).sum())
                count += own[:, inside].size
    return total / count if count else float("nan")


def lookups(rig: Rig, grid_hw: tuple[int, int], max_ground_m: float):
    """Per view of ``rig``, in rig order: where every camera (the view's own among them) sees the
    flat-world points of the view's pixels, an (x, y) pair of (N,) arrays per camera
    (:func:`drivewm.views.warp.source_pixels`; NaN behind it)."""
    for cam in rig.cameras:
        ground, point, d = flat_world_points(cam, grid_hw, np.eye(4), max_ground_m)
        yield [source_pixels(src, grid_hw, ground, point, d) for src in rig.cameras]


def check_views(views: np.ndarray, rig: Rig) -> None:
    """ValueError unless ``views`` holds one view per camera of ``rig``."""
    if len(views) != len(rig.cameras):
        raise ValueError(f"{len(views)} views for a rig of {len(rig.cameras)} cameras")


def sample_frames(frames: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Colours float32 (T, N, C) of frames (T, H, W, C; uint8 or float) at pixel coordinates ``x``,
    ``y`` (N,), bilinear, clamped to the image (NaN read as 0: weigh them out). float32 holds every
    value exactly that float64 arithmetic on it needs (the callers' sums are float64)."""
    t, h, w, _ = frames.shape
    images = torch.from_numpy(np.ascontiguousarray(frames)).float().permute(0, 3, 1, 2)
    grid = np.stack([(np.nan_to_num(x) + 0.5) / w * 2 - 1, (np.nan_to_num(y) + 0.5) / h * 2 - 1], axis=1)
    grid = torch.from_numpy(grid.astype(np.float32)).view(1, 1, -1, 2).expand(t, -1, -1, -1)
    colour = F.grid_sample(images, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return colour[:, :, 0].numpy().transpose(0, 2, 1)  # a view: no copy
