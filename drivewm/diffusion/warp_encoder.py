"""The warped source latents as token input: a zero-initialised patch projection (a fresh model ignores it)."""

from __future__ import annotations

import torch
from torch import nn

from drivewm.diffusion.dit import patchify


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
