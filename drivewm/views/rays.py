"""Rays of a rig's pixels and tokens: per-token Plucker rays in the ego frame, static or moving.

A token of view v at latent patch (row i, column j) looks along the ray through the centre of its
image patch. In the ego frame that ray has origin o (the camera centre) and unit direction d, and
its Plucker coordinates (d, o x d) (Plucker 1865; used for camera conditioning by e.g. Sitzmann et
al. 2021, "Light Field Networks") identify it independently of where along the ray o sits.
Computed from each camera's K and T_ego_from_cam alone.
"""

from __future__ import annotations

import numpy as np
import torch
from einops import rearrange, repeat

from drivewm.geometry import Camera, Rig, pixel_rays


def patch_centres_px(camera: Camera, grid_hw: tuple[int, int]) -> np.ndarray:
    """(h*w, 2) pixel (u, v) of the centres of an h x w token grid over the camera's image, row-major."""
    h, w = grid_hw
    u = (np.arange(w) + 0.5) * camera.width / w - 0.5  # pixel centres are at integer coordinates
    v = (np.arange(h) + 0.5) * camera.height / h - 0.5
    uu, vv = np.meshgrid(u, v, indexing="xy")
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def plucker_rays(rig: Rig, grid_hw: tuple[int, int]) -> torch.Tensor:
    """(V, h*w, 6) float32 Plucker coordinates (d, o x d) in the ego frame (metres) of each view's
    token-grid patch centres, in rig order and row-major over (row, column)."""
    out = []
    for cam in rig.cameras:
        d_cam = pixel_rays(cam.K, patch_centres_px(cam, grid_hw))  # (hw, 3) in the camera frame
        d = d_cam @ cam.T_ego_from_cam[:3, :3].T
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(cam.T_ego_from_cam[:3, 3], d.shape)
        out.append(np.concatenate([d, np.cross(o, d)], axis=1))
    return torch.from_numpy(np.stack(out)).float()


def token_rays(rays_hw: torch.Tensor, num_frames: int) -> torch.Tensor:
    """(V, h*w, 6) -> (V, t*h*w, 6): the rig is rigid, so every latent frame has the same rays
    (tokens are row-major over (t, h, w), drivewm.diffusion.dit.patchify)."""
    return repeat(rays_hw, "v hw c -> v (t hw) c", t=num_frames)


def moving_token_rays(rays_hw: torch.Tensor, T_ego0_from_ego: torch.Tensor) -> torch.Tensor:
    """Rays of a moving rig: (V, h*w, 6) in the ego frame and the ego pose of every latent frame
    (t, 4, 4) in the first frame's ego frame -> (V, t*h*w, 6) in that first ego frame.

    A Plucker line (d, m) moves with a rigid motion (R, p) as d' = R d, m' = R m + p x d'."""
    R, p = T_ego0_from_ego[:, :3, :3].to(rays_hw), T_ego0_from_ego[:, :3, 3].to(rays_hw)  # (t, 3, 3), (t, 3)
    d = torch.einsum("tij,vnj->vtni", R, rays_hw[..., :3])  # (V, t, hw, 3)
    m = torch.einsum("tij,vnj->vtni", R, rays_hw[..., 3:]) + torch.cross(p[None, :, None].expand_as(d), d, dim=-1)
    return rearrange(torch.cat([d, m], dim=-1), "v t n c -> v (t n) c")
