"""Haar-wavelet patching at the tokenizer's input and output (Cosmos Tokenizer, arXiv 2501.03575 sec. 3.1).

The orthonormal 2x2 Haar transform moves each 2x2 pixel block into 4 channels (LL, LH, HL, HH),
so the first layers see a half-resolution signal with no information lost. The temporal step
pairs frames (1, 2), (3, 4), ...; the first frame is paired with a copy of itself, so it is
coded alone (causality: nothing ever looks ahead). Both steps are exactly invertible.
"""

from __future__ import annotations

import math

import torch
from einops import rearrange

SQRT2 = math.sqrt(2.0)


def haar_space(x: torch.Tensor) -> torch.Tensor:
    """(B, C, T, H, W) -> (B, 4C, T, H/2, W/2): channels ordered (subband, C)."""
    a, b = x[..., 0::2, 0::2], x[..., 0::2, 1::2]
    c, d = x[..., 1::2, 0::2], x[..., 1::2, 1::2]
    return torch.cat([a + b + c + d, a - b + c - d, a + b - c - d, a - b - c + d], dim=1) / 2


def inverse_haar_space(y: torch.Tensor) -> torch.Tensor:
    """(B, 4C, T, h, w) -> (B, C, T, 2h, 2w); the inverse of :func:`haar_space`."""
    ll, lh, hl, hh = y.chunk(4, dim=1)
    a, b = (ll + lh + hl + hh) / 2, (ll - lh + hl - hh) / 2
    c, d = (ll + lh - hl - hh) / 2, (ll - lh - hl + hh) / 2
    top = rearrange([a, b], "two b c t h w -> b c t h (w two)")
    bottom = rearrange([c, d], "two b c t h w -> b c t h (w two)")
    return rearrange([top, bottom], "two b c t h w -> b c t (h two) w")


def haar_time(x: torch.Tensor, first_chunk: bool = True) -> torch.Tensor:
    """(B, C, T, H, W) -> (B, 2C, T', H, W), T' = (T+1)/2 for a first chunk, else T/2.

    A first chunk (T = 1 + 2k) starts with frame 0 paired with itself; a continuation chunk
    (T = 2k, the frames after a previous chunk) pairs its frames as they come.
    """
    if first_chunk:
        x = torch.cat([x[:, :, :1], x], dim=2)
    p, q = x[:, :, 0::2], x[:, :, 1::2]
    return torch.cat([p + q, p - q], dim=1) / SQRT2


def inverse_haar_time(y: torch.Tensor, first_chunk: bool = True) -> torch.Tensor:
    """(B, 2C, T', H, W) -> (B, C, T, H, W); drops the duplicated frame 0 of a first chunk."""
    low, high = y.chunk(2, dim=1)
    x = rearrange([(low + high) / SQRT2, (low - high) / SQRT2], "two b c t h w -> b c (t two) h w")
    return x[:, :, 1:] if first_chunk else x
