"""Finite scalar quantization (Mentzer et al. 2023, "Finite Scalar Quantization: VQ-VAE Made Simple",
arXiv 2309.15505, Appendix A.1).

Each latent channel i is bounded to ``levels[i]`` values and rounded with a straight-through
gradient; the implicit codebook is the product of the levels. No codebook to learn, no
commitment loss, and no collapse by construction.
"""

from __future__ import annotations

import torch
from torch import nn


class FSQ(nn.Module):
    """Quantize (B, d, t, h, w) latents, d = len(levels), to values in [-1, 1]."""

    def __init__(self, levels: list[int], eps: float = 1e-3):
        super().__init__()
        levels_t = torch.tensor(levels, dtype=torch.float64)
        basis = torch.cumprod(torch.tensor([1] + list(levels[:-1]), dtype=torch.int64), dim=0)
        self.eps = eps
        self.register_buffer("levels", levels_t.float().view(1, -1, 1, 1, 1), persistent=False)
        self.register_buffer("basis", basis.view(1, -1, 1, 1, 1), persistent=False)
        self.codebook_size = int(torch.prod(levels_t).item())

    def bound(self, z: torch.Tensor) -> torch.Tensor:
        """Squash channel i into (-L_i/2, L_i/2) so rounding gives exactly L_i values (paper eq. in A.1)."""
        half_l = (self.levels - 1) * (1 - self.eps) / 2
        offset = torch.where(self.levels % 2 == 0, 0.5, 0.0)
        shift = torch.atanh(offset / half_l)
        return torch.tanh(z + shift) * half_l - offset

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        bounded = self.bound(z)
        quantized = bounded + (torch.round(bounded) - bounded).detach()  # straight-through estimator
        return quantized / (self.levels // 2)

    def codes_to_indices(self, codes: torch.Tensor) -> torch.Tensor:
        """(B, d, t, h, w) quantized codes -> (B, t, h, w) int64 indices in [0, codebook_size)."""
        half = self.levels // 2
        digits = torch.round(codes * half + half).long()
        return (digits * self.basis).sum(dim=1)

    def indices_to_codes(self, indices: torch.Tensor) -> torch.Tensor:
        """(B, t, h, w) int64 indices -> (B, d, t, h, w) codes (the inverse of :meth:`codes_to_indices`)."""
        digits = (indices.unsqueeze(1) // self.basis) % self.levels.long()
        half = self.levels // 2
        return (digits.float() - half) / half
