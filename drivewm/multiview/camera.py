"""Camera conditioning from calibration: per-token Plucker rays (drivewm.views.rays) -> DiT token offsets.

A token of view v at latent patch (row i, column j) looks along the ray through the centre of its
image patch. In the ego frame that ray has origin o (the camera centre) and unit direction d, and
its Plucker coordinates (d, o x d) (Plucker 1865; used for camera conditioning by e.g. Sitzmann et
al. 2021, "Light Field Networks") identify it independently of where along the ray o sits.
Computed from each camera's K and T_ego_from_cam alone, so a rig with another number, order or
placement of cameras needs no embedding table: only its calibration.
"""

from __future__ import annotations

import torch
from torch import nn


class CameraEncoder(nn.Module):
    """Plucker rays (..., 6) -> token offsets (..., D): moments scaled to O(1), then Linear -> SiLU ->
    Linear (the last zero-initialised, so a fresh encoder adds nothing and the model starts as its
    Text2World parent)."""

    def __init__(self, hidden_dim: int, width: int = 128, moment_scale_m: float = 10.0):
        super().__init__()
        self.moment_scale_m = moment_scale_m  # o x d grows with the distance of the camera from the origin
        self.net = nn.Sequential(nn.Linear(6, width), nn.SiLU(), nn.Linear(width, hidden_dim))
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def forward(self, rays: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([rays[..., :3], rays[..., 3:] / self.moment_scale_m], dim=-1))
