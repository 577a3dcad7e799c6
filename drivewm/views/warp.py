"""The flat-world warp: the first frame of every view rendered into every later frame's cameras
along an ego trajectory (used by the ``reproject`` post-step and by the overlap blend).

A later frame of a camera sees (mostly) what some camera saw in the first frame, moved across the
image by the ego's turn and travel. The warp renders that for every latent pixel: its ray from
the camera's pose at that frame (rig calibration + trajectory) is followed to the road, a plane
at the ego frame's z = 0, or, above the horizon or beyond ``max_ground_m``, to infinity; that
point is looked up in whichever view's first frame sees it (the same view first, then the others,
so a left turn fetches content from the front-left camera). Road and distant scenery are exact;
anything standing on the road (cars, buildings) is wrong by its parallax, which the network has to
correct. It is GEN3C's idea (Ren et al. 2025: render a 3D cache into the target cameras as
conditioning) with a flat-world depth (inverse perspective mapping's road plane plus the plane at
infinity) in place of a depth map, so it needs nothing but K, T_ego_from_cam and the waypoints:
any rig works. Invalid pixels (no view saw that direction) are zero with mask 0.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from einops import rearrange

from drivewm.geometry import Camera, Rig, pixel_rays, project
from drivewm.views.rays import patch_centres_px


def warp_grid(
    rig: Rig,
    latent_hw: tuple[int, int],
    T_ego0_from_ego: np.ndarray,
    max_ground_m: float = 100.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Sampling positions of every view's latent pixels in the first frame of the rig.

    ``T_ego0_from_ego`` (T, 4, 4): the ego pose of every latent frame in the first frame's ego frame.
    A ray that meets the ground (z = 0 of the ego frame, which sits on the road) within
    ``max_ground_m`` is followed to that point; any other ray is a direction at infinity.
    Returns ``grid`` (V, T, h, w, 2) in :func:`torch.nn.functional.grid_sample` coordinates
    (align_corners=False) over the views' first latent frames laid side by side (V*w wide, rig
    order) and ``valid`` (V, T, h, w) bool.
    """
    h, w = latent_hw
    v_count = len(rig.cameras)
    grid = np.zeros((v_count, len(T_ego0_from_ego), h, w, 2))
    valid = np.zeros((v_count, len(T_ego0_from_ego), h, w), dtype=bool)
    for v, cam in enumerate(rig.cameras):
        for t, T in enumerate(T_ego0_from_ego):
            ground, point, d = flat_world_points(cam, latent_hw, T, max_ground_m)
            found = np.zeros(len(d), dtype=bool)
            for s in [v, *[k for k in range(v_count) if k != v]]:  # own view first
                x, y = source_pixels(rig.cameras[s], latent_hw, ground, point, d)
                eps = 1e-6  # a pixel's own centre maps back onto itself up to rounding
                ok = ~found & (x >= -eps) & (x <= w - 1 + eps) & (y >= -eps) & (y <= h - 1 + eps)
                x, y = np.clip(x, 0, w - 1), np.clip(y, 0, h - 1)
                gx = (s * w + x + 0.5) / (v_count * w) * 2 - 1  # within strip s: no bleed into neighbours
                gy = (y + 0.5) / h * 2 - 1
                grid[v, t].reshape(-1, 2)[ok] = np.stack([gx[ok], gy[ok]], axis=1)
                found |= ok
            valid[v, t] = found.reshape(h, w)
    return torch.from_numpy(grid).float(), torch.from_numpy(valid)


def flat_world_points(
    cam: Camera, grid_hw: tuple[int, int], T_ego0_from_ego: np.ndarray, max_ground_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The flat world :func:`warp_grid` renders, for one camera of the rig at ego pose ``T_ego0_from_ego``
    (4, 4; in the first ego frame): the ray through each centre of an h x w grid over its image
    (row-major) followed to the road within ``max_ground_m`` (``ground``
    (N,) bool, ``point`` (N, 3) m there) or else to infinity (direction ``d`` (N, 3))."""
    T_cam = T_ego0_from_ego @ cam.T_ego_from_cam  # this camera, in the first ego frame
    d = pixel_rays(cam.K, patch_centres_px(cam, grid_hw)) @ T_cam[:3, :3].T
    o = T_cam[:3, 3]
    depth = ray_depths(o, d)
    ground = depth < max_ground_m  # a point on the road; the rest at infinity
    point = o + np.where(ground, depth, 0.0)[:, None] * d  # ground points; other rows unused
    return ground, point, d


def source_pixels(
    src: Camera, grid_hw: tuple[int, int], ground: np.ndarray, point: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where camera ``src`` of the first frame sees :func:`flat_world_points`' points: x and y (N,) in
    the coordinates of an h x w grid over its image (NaN behind it; no bounds check)."""
    h, w = grid_hw
    R_s, c_s = src.T_ego_from_cam[:3, :3], src.T_ego_from_cam[:3, 3]  # first frame: ego0 = ego
    px, _ = project(src.K, np.where(ground[:, None], point - c_s, d) @ R_s)
    return (px[:, 0] + 0.5) * w / src.width - 0.5, (px[:, 1] + 0.5) * h / src.height - 0.5


def ray_depths(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance along each ray ``o + s d`` (d (N, 3), first ego frame: x forward, y left, z up) to the
    road (z = 0); inf where it never meets it."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d[:, 2] < 0, -o[2] / d[:, 2], np.inf)


def warp_first_frame(
    cond_latents: torch.Tensor, grid: torch.Tensor, valid: torch.Tensor, num_views: int
) -> torch.Tensor:
    """(B V, c, T, h, w) clean latents (first frame used) -> (B V, c + 1, T, h, w): the first frames
    warped by ``grid`` (B V, T, h, w, 2) where ``valid`` (B V, T, h, w), zero elsewhere, plus the mask."""
    first = rearrange(cond_latents[:, :, 0], "(b v) c h w -> b c h (v w)", v=num_views)
    g = rearrange(grid.to(first), "(b v) t h w k -> b (v t h) w k", v=num_views)
    warped = F.grid_sample(first, g, mode="bilinear", padding_mode="zeros", align_corners=False)  # (B, c, V*T*h, w)
    t, h = grid.shape[1], grid.shape[2]
    warped = rearrange(warped, "b c (v t h) w -> (b v) c t h w", v=num_views, t=t, h=h)
    mask = valid.to(warped)[:, None]
    return torch.cat([warped * mask, mask], dim=1)
