"""Noise warped along the ego trajectory: the diffusion noise of later latent frames moves with the rig.

Independent noise per frame leaves the motion of a sample to the network alone, and the CPU-trained
models carry the trajectory too weakly for it to survive sampling (docs/quality-vs-compute.md). Warped
noise puts the motion into the noise itself, as Go-with-the-Flow does with optical flow (Burgert et
al. 2025, arXiv 2501.08331) and PYoCo with its correlated per-frame noise (Ge et al. 2023, arXiv
2305.10474): every later latent frame's noise is the first frame's, moved along the trajectory, mixed
with fresh noise,

    n_t = a * warp_t(n_0) + sqrt(1 - a^2) * e_t   where the warp finds a source pixel, e_t elsewhere,

so every value stays standard normal and a (``multiview.warped_noise``) is the correlation along the
motion. The warp is :func:`drivewm.views.warp.warp_grid`'s (rig calibration and waypoints, the
road plane and the plane at infinity; a left turn fetches from the front-left camera), sampled at the
nearest latent pixel so values are copied, never averaged (an average of normals is not unit normal).
A model learns what warped noise means in training (the clip's own trajectory warps its noise) and
is sampled with noise warped along the trajectory asked for. Off by default: at the CPU budget
measured so far (1,000 fine-tuning steps of the shipped model), warped noise does not yet steer the
samples (``studies/noise_steering.py``, docs/quality-vs-compute.md, "Warped noise").
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from einops import rearrange


def warp_noise(noise: torch.Tensor, grid: torch.Tensor, valid: torch.Tensor, num_views: int, a: float) -> torch.Tensor:
    """(B V, c, T, h, w) independent standard normal noise -> the same shape, each later frame the first
    frame's noise warped by ``grid`` (B V, T, h, w, 2) (:func:`drivewm.views.warp.warp_grid`'s, over
    the views side by side) with weight ``a``, and its own noise with weight sqrt(1 - a^2); its own
    noise alone where ``valid`` (B V, T, h, w) is False. The first frame is unchanged; a = 0 is the
    identity."""
    if not 0 <= a < 1:
        raise ValueError(f"warped noise: a must be in [0, 1), got {a}")
    if a == 0:
        return noise
    t, h = noise.shape[2], noise.shape[3]
    first = rearrange(noise[:, :, 0], "(b v) c h w -> b c h (v w)", v=num_views)
    g = rearrange(grid.to(first), "(b v) t h w k -> b (v t h) w k", v=num_views)
    warped = F.grid_sample(first, g, mode="nearest", padding_mode="zeros", align_corners=False)
    warped = rearrange(warped, "b c (v t h) w -> (b v) c t h w", v=num_views, t=t, h=h)
    mask = valid.to(noise.device)[:, None]
    out = torch.where(mask, a * warped + math.sqrt(1 - a * a) * noise, noise)
    out[:, :, 0] = noise[:, :, 0]
    return out
