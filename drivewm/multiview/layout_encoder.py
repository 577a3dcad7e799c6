"""The layout encoder: the tokenizer's code of a per-camera layout video (drivewm.layout.render) ->
one embedding per DiT token.

The layout video is coded by the same tokenizer as the clip, so its latents share the clip's token
grid: a patch embedding (the DiT's own patchify) and an MLP give each token the layout it covers. The
last layer starts at zero, so a model given a new layout encoder starts as the model without it. A
view whose layout is dropped (training dropout, or generation without a layout) gets a zero embedding:
the model's "no layout" input (multi-view config ``layout``: added to the patch tokens, or fed to the
DiT's ControlNet branch).
"""

from __future__ import annotations

import torch
from torch import nn

from drivewm.diffusion.dit import patchify


class LayoutEncoder(nn.Module):
    """``forward(layout (B V, c, t, h, w) normalised latents or None, keep (B V,) bool or None, n_tokens)
    -> (B V, N, D)``."""

    def __init__(self, in_channels: int, dim: int, patch_size: int, patch_t: int):
        super().__init__()
        self.patch_size, self.patch_t, self.dim = patch_size, patch_t, dim
        self.mlp = nn.Sequential(
            nn.Linear(in_channels * patch_t * patch_size**2, dim),  # one patch of layout latents
            nn.GELU(approximate="tanh"),
            nn.Linear(dim, dim),
        )
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, layout: torch.Tensor | None, keep: torch.Tensor | None, like: torch.Tensor) -> torch.Tensor:
        """Embeddings of ``layout``; zeros for views with ``keep`` False, and for all without a layout.
        ``like`` (B V, c, t, h, w): the noisy latents, for the token count, dtype and device."""
        if layout is None:
            b, _, t, h, w = like.shape
            n = (t // self.patch_t) * (h // self.patch_size) * (w // self.patch_size)
            return like.new_zeros(b, n, self.dim)
        emb = self.mlp(patchify(layout.to(like.dtype), self.patch_size, self.patch_t))  # (B V, N, D)
        return emb if keep is None else emb * keep[:, None, None].to(emb.dtype)
