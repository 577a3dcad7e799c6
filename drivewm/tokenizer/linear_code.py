"""A linear transform code beside the tokenizer's networks, started at the PCA of the training blocks.

Each latent position codes one block of ``temporal_compression x spatial_compression^2`` pixels of
3 colours (768 values at 4x8x8). The best *linear* code of such blocks into c numbers is their
principal components (Karhunen-Loeve), and it is a strong baseline: on held-out simulated drives
PCA with the tokenizer's 16 channels scores 30.1 dB where a 1.4M-parameter network trained
3,500 steps scores 29.1 (docs/results.md). So the network is given that code as a path of its
own and learns only what the linear code misses:

    z = P (fold(patch(x)) - mu) + encoder(patch(x))          (c, t, h, w)
    x' = unpatch(unfold(P^T z + mu) + decoder(z))

with P (c x K) the top principal directions and mu the mean block, both trainable, and the
networks' output heads started at zero, so the untrained tokenizer *is* the PCA codec. This is
DC-AE's residual autoencoding (Chen et al. 2024, arXiv 2410.10733, sec. 3.2) with the shortcut
fitted to the data instead of fixed to channel averaging.

The Haar patch is orthonormal, so the PCA of the folded Haar coefficients is the PCA of the pixel
blocks. ``fold`` stacks the ``(temporal_compression / patch_time) x (spatial_compression /
patch_size)^2`` Haar cells of one latent position into channels; in time it is causal like the
network's downsampling: a first chunk repeats frame 0's cell, so latent frame 0 codes frame 0 alone.
"""

from __future__ import annotations

import torch
from einops import rearrange
from torch import nn

from drivewm.tokenizer.config import TokenizerConfig


class LinearCode(nn.Module):
    """The linear path: Haar coefficients (B, patch_channels, T', H', W') <-> latents (B, c, t, h, w)."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        self.ft = cfg.temporal_compression // cfg.patch_time  # Haar cells folded in time
        self.fs = cfg.spatial_compression // cfg.patch_size  # ... and in each of height and width
        self.block = cfg.patch_channels * self.ft * self.fs**2  # K values per latent position
        self.basis = nn.Parameter(torch.zeros(cfg.code_channels, self.block))  # P (c, K): rows orthonormal once fitted
        self.mean = nn.Parameter(torch.zeros(self.block))  # mu (K,)

    def fold(self, x: torch.Tensor, first_chunk: bool) -> torch.Tensor:
        """(B, C, T', H', W') -> (B, K, t, h, w)."""
        if first_chunk and self.ft > 1:
            x = torch.cat([x[:, :, :1].expand(-1, -1, self.ft - 1, -1, -1), x], dim=2)
        return rearrange(x, "b c (t a) (h p) (w q) -> b (a p q c) t h w", a=self.ft, p=self.fs, q=self.fs)

    def unfold(self, y: torch.Tensor, first_chunk: bool) -> torch.Tensor:
        """(B, K, t, h, w) -> (B, C, T', H', W'); the inverse of :meth:`fold`."""
        x = rearrange(y, "b (a p q c) t h w -> b c (t a) (h p) (w q)", a=self.ft, p=self.fs, q=self.fs)
        return x[:, :, self.ft - 1 :] if first_chunk else x

    def encode(self, x: torch.Tensor, first_chunk: bool) -> torch.Tensor:
        """Haar coefficients -> the linear part of the latents, P (fold(x) - mu)."""
        blocks = self.fold(x, first_chunk) - self.mean[:, None, None, None]  # (B, K, t, h, w)
        return torch.einsum("ck,bkthw->bcthw", self.basis, blocks)

    def decode(self, z: torch.Tensor, first_chunk: bool) -> torch.Tensor:
        """Latents -> the linear part of the Haar coefficients, unfold(P^T z + mu)."""
        blocks = torch.einsum("ck,bcthw->bkthw", self.basis, z) + self.mean[:, None, None, None]
        return self.unfold(blocks, first_chunk)

    @torch.no_grad()
    def fit(self, patches: list[torch.Tensor]) -> torch.Tensor:
        """Set P and mu to the principal components of the blocks of ``patches`` (Haar coefficients of
        first chunks, each (B, C, T', H', W')); returns the variance per component (descending)."""
        blocks = torch.cat([self.fold(p, True).transpose(0, 1).flatten(1) for p in patches], 1).double()  # (K, N)
        mean = blocks.mean(1)
        centred = blocks - mean[:, None]
        variance, vectors = torch.linalg.eigh(centred @ centred.T / centred.shape[1])  # ascending
        top = vectors[:, -self.basis.shape[0] :].flip(1).T  # (c, K), largest variance first
        self.basis.copy_(top.to(self.basis.dtype))
        self.mean.copy_(mean.to(self.mean.dtype))
        return variance.flip(0)
