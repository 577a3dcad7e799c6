"""Ego-trajectory conditioning: future waypoints (W, 3) in the first frame's ego frame -> a (D,)
vector added to the DiT's timestep embedding (``extra_global_cond``), so every AdaLN modulation of
every block sees it (as Cosmos feeds its class/time conditioning; MagicDrive and Drive-WM condition
on ego motion the same way through a global embedding)."""

from __future__ import annotations

import torch
from einops import rearrange
from torch import nn

from drivewm.errors import DrivewmError


class TrajectoryEncoder(nn.Module):
    """(B, W, 3) waypoints (m) -> (B, D): scale to O(1), flatten, Linear -> SiLU -> Linear (last one
    zero-initialised, so a fresh encoder leaves the parent model unchanged)."""

    def __init__(self, num_waypoints: int, hidden_dim: int, width: int = 256, scale_m: float = 20.0):
        super().__init__()
        self.num_waypoints = num_waypoints  # W, fixed by the training data (ClipMeta.trajectory_ego)
        self.scale_m = scale_m  # waypoints / scale_m are O(1) at driving speeds over ~2 s
        self.net = nn.Sequential(nn.Linear(3 * num_waypoints, width), nn.SiLU(), nn.Linear(width, hidden_dim))
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def forward(self, waypoints_m: torch.Tensor) -> torch.Tensor:
        if waypoints_m.shape[-2:] != (self.num_waypoints, 3):
            raise DrivewmError(
                f"trajectory: expected (B, {self.num_waypoints}, 3) waypoints, got {tuple(waypoints_m.shape)}"
            )
        return self.net(rearrange(waypoints_m / self.scale_m, "b w c -> b (w c)"))
