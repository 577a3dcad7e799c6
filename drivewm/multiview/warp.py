"""Reprojected Video2World conditioning: the given first latent frame of every view, warped into
every later latent frame's cameras along the conditioned ego trajectory, as extra token input.

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
any rig works.

The network sees the warp through a zero-initialised patch projection added to its tokens
(:class:`WarpEncoder`), so a fresh multi-view model is still its Text2World parent; it learns how
much to trust the warp. Invalid pixels (no view saw that direction) are zero with mask 0.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from drivewm.diffusion.dit import patchify
from drivewm.errors import DrivewmError
from drivewm.geometry import Camera, Rig, pixel_rays, project
from drivewm.multiview.camera import patch_centres_px


def warp_grid(
    rig: Rig,
    latent_hw: tuple[int, int],
    T_ego0_from_ego: np.ndarray,
    max_ground_m: float = 100.0,
    walls_m: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Sampling positions of every view's latent pixels in the first frame of the rig.

    ``T_ego0_from_ego`` (T, 4, 4): the ego pose of every latent frame in the first frame's ego frame.
    A ray that meets the ground (z = 0 of the ego frame, which sits on the road) within
    ``max_ground_m`` is followed to that point; any other ray is a direction at infinity.
    ``walls_m`` > 0 adds a corridor: two vertical planes at y = +-walls_m of the first ego frame,
    up to :data:`WALL_HEIGHT_M`; a ray that meets one within ``max_ground_m`` before the ground
    stops there (:func:`ray_depths`), so what stands beside the road passes by with parallax
    instead of staying at infinity.
    Returns ``grid`` (V, T, h, w, 2) in :func:`torch.nn.functional.grid_sample` coordinates
    (align_corners=False) over the views' first latent frames laid side by side (V*w wide, rig
    order) and ``valid`` (V, T, h, w) bool. A corridor that some camera of the rig stands outside of
    (at the first frame) is a DrivewmError: its walls would hide the road from that camera.
    """
    check_corridor(rig, walls_m)
    h, w = latent_hw
    v_count = len(rig.cameras)
    grid = np.zeros((v_count, len(T_ego0_from_ego), h, w, 2))
    valid = np.zeros((v_count, len(T_ego0_from_ego), h, w), dtype=bool)
    for v, cam in enumerate(rig.cameras):
        for t, T in enumerate(T_ego0_from_ego):
            ground, point, d = flat_world_points(cam, latent_hw, T, max_ground_m, walls_m)
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
    cam: Camera, grid_hw: tuple[int, int], T_ego0_from_ego: np.ndarray, max_ground_m: float, walls_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The flat world :func:`warp_grid` renders, for one camera of the rig at ego pose ``T_ego0_from_ego``
    (4, 4; in the first ego frame): the ray through each centre of an h x w grid over its image
    (row-major) followed to the road or a wall of the corridor within ``max_ground_m`` (``ground``
    (N,) bool, ``point`` (N, 3) m there) or else to infinity (direction ``d`` (N, 3))."""
    T_cam = T_ego0_from_ego @ cam.T_ego_from_cam  # this camera, in the first ego frame
    d = pixel_rays(cam.K, patch_centres_px(cam, grid_hw)) @ T_cam[:3, :3].T
    o = T_cam[:3, 3]
    depth = ray_depths(o, d, walls_m)
    ground = depth < max_ground_m  # a point on the road or a wall; the rest at infinity
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


def check_corridor(rig: Rig, walls_m: float) -> None:
    """DrivewmError unless every camera of ``rig`` stands inside the corridor of ``walls_m`` (or there
    is none, ``walls_m`` 0)."""
    if walls_m <= 0:
        return
    widest = max(rig.cameras, key=lambda cam: abs(cam.T_ego_from_cam[1, 3]))
    y = float(widest.T_ego_from_cam[1, 3])
    if abs(y) >= walls_m:
        raise DrivewmError(
            f"warp: a corridor of walls {walls_m:g} m left and right leaves camera {widest.name} outside it "
            f"({y:+.2f} m to the side); give a wider corridor than the rig (measured widths: 6-40 m) or 0"
        )


WALL_HEIGHT_M = 30.0
"""Top of the corridor's walls (``walls_m``): rays above it go to infinity (sky, far scenery)."""


def ray_depths(o: np.ndarray, d: np.ndarray, walls_m: float = 0.0) -> np.ndarray:
    """Distance along each ray ``o + s d`` (d (N, 3), first ego frame: x forward, y left, z up) to
    the first surface it meets: the road (z = 0) and, with ``walls_m`` > 0, the corridor's walls
    (y = +-walls_m, 0 <= z <= :data:`WALL_HEIGHT_M`); inf where it meets none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(d[:, 2] < 0, -o[2] / d[:, 2], np.inf)  # along d to the road
        if walls_m > 0:
            side = np.where(d[:, 1] >= 0, walls_m, -walls_m)  # the wall the ray heads for
            wall = np.where(d[:, 1] != 0, (side - o[1]) / d[:, 1], np.inf)
            z = o[2] + wall * d[:, 2]
            wall = np.where((wall > 0) & (z >= 0) & (z <= WALL_HEIGHT_M), wall, np.inf)
            depth = np.minimum(depth, wall)
    return depth


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


class WarpEncoder(nn.Module):
    """Warped first frames + mask (B V, c + 1, T, h, w) -> token offsets (B V, N, D): patchified like
    the DiT's input and projected by one zero-initialised linear layer (a fresh model ignores it)."""

    def __init__(self, latent_channels: int, hidden_dim: int, patch_size: int, patch_t: int):
        super().__init__()
        self.patch_size, self.patch_t = patch_size, patch_t
        self.proj = nn.Linear((latent_channels + 1) * patch_t * patch_size**2, hidden_dim)
        nn.init.zeros_(self.proj.weight)
        nn.init.zeros_(self.proj.bias)

    def forward(self, warped: torch.Tensor) -> torch.Tensor:
        return self.proj(patchify(warped, self.patch_size, self.patch_t))
