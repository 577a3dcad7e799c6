"""A clip's first frame rendered along an ego trajectory over a flat world (drivewm.views.warp), in pixels."""

from __future__ import annotations

import numpy as np
import torch
from einops import rearrange

from drivewm.geometry import Rig, invert_T
from drivewm.views.reshade import reshade as reshade_road
from drivewm.views.warp import warp_first_frame, warp_grid


def reproject_first_frame(
    videos: np.ndarray,
    rig: Rig,
    T_world_from_ego: np.ndarray,
    max_ground_m: float = 100.0,
    reshade: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """uint8 (V, T, H, W, 3) views of ``rig`` -> the same shape, frame 0 of every view rendered at every
    frame's ego pose ``T_world_from_ego`` (T, 4, 4); pixels no view's first frame sees keep the input's
    own. Also the pixels rendered, bool (V, T, H, W). ``reshade``: the road given the first frame's look
    at its own distance (drivewm.views.reshade)."""
    v, t, h, w, _ = videos.shape
    rel = np.einsum("ij,tjk->tik", invert_T(T_world_from_ego[0]), T_world_from_ego)  # (T, 4, 4) in ego frame 0
    grid, valid = warp_grid(rig, (h, w), rel, max_ground_m)
    frames = rearrange(torch.from_numpy(videos).float(), "v t h w c -> v c t h w")
    warped = warp_first_frame(frames, grid, valid, v)[:, :3]  # (V, 3, T, H, W), zero where not valid
    keep = valid[:, None].float()
    out = warped * keep + frames * (1 - keep)
    out = rearrange(out, "v c t h w -> v t h w c").round().clamp(0, 255).byte().numpy()
    if reshade:
        out = reshade_road(out, valid.numpy(), rig, rel)
    return out, valid.numpy()
