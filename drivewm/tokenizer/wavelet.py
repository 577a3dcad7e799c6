"""Haar-wavelet patching at the tokenizer's input and output (Cosmos Tokenizer, arXiv 2501.03575 sec. 3.1).

The orthonormal 2x2 Haar transform moves each 2x2 pixel block into 4 channels (LL, LH, HL, HH),
so the first layers see a half-resolution signal with no information lost. The temporal step
pairs frames (1, 2), (3, 4), ...; the first frame is paired with a copy of itself, so it is
coded alone (causality: nothing ever looks ahead). Both steps are exactly invertible.
"""

from __future__ import annotations

import functools
import math

import torch
import torch.nn.functional as F
from einops import rearrange

SQRT2 = math.sqrt(2.0)


def haar_space(x: torch.Tensor) -> torch.Tensor:
    """(B, C, T, H, W) -> (B, 4C, T, H/2, W/2): channels ordered (subband, C)."""
    a, b = x[..., 0::2, 0::2], x[..., 0::2, 1::2]
    c, d = x[..., 1::2, 0::2], x[..., 1::2, 1::2]
    return torch.cat([a + b + c + d, a - b + c - d, a + b - c - d, a - b - c + d], dim=1) / 2


def haar_time(x: torch.Tensor, first_chunk: bool = True) -> torch.Tensor:
    """(B, C, T, H, W) -> (B, 2C, T', H, W), T' = (T+1)/2 for a first chunk, else T/2.

    A first chunk (T = 1 + 2k) starts with frame 0 paired with itself; a continuation chunk
    (T = 2k, the frames after a previous chunk) pairs its frames as they come.
    """
    if first_chunk:
        x = torch.cat([x[:, :, :1], x], dim=2)
    p, q = x[:, :, 0::2], x[:, :, 1::2]
    return torch.cat([p + q, p - q], dim=1) / SQRT2


def patchify(video: torch.Tensor, patch_size: int, patch_time: int, first_chunk: bool = True) -> torch.Tensor:
    """(B, C, T, H, W) -> (B, C * patch_size^2 * patch_time, T', H/patch_size, W/patch_size).

    Equal to the 2x2 spatial Haar step applied log2(patch_size) times, then the causal temporal
    step log2(patch_time) times (channels ordered (subband, C), as those steps order them), computed
    as one strided 2D convolution with the orthonormal :func:`haar_matrix` (the patch's frames as
    input channels): the nested steps run many strided elementwise passes over full-resolution
    frames and cost 2-3x more. A first chunk of T = 1 + k*patch_time frames starts with frame 0
    repeated, so frame 0 is coded alone (T' = 1 + k); a continuation chunk of k*patch_time frames
    gives T' = k.
    """
    if first_chunk and patch_time > 1:
        video = torch.cat([video[:, :, :1].expand(-1, -1, patch_time - 1, -1, -1), video], dim=2)
    b, c, t, h, w = video.shape
    frames = video.reshape(b * c * (t // patch_time), patch_time, h, w)  # a view: patches' frames as channels
    coeffs = F.conv2d(frames, _haar_kernel(patch_size, patch_time, video), stride=patch_size)  # (B C T', K, h, w)
    return rearrange(coeffs, "(b c t) k h w -> b (k c) t h w", b=b, c=c)


def unpatchify(y: torch.Tensor, patch_size: int, patch_time: int, first_chunk: bool = True) -> torch.Tensor:
    """The inverse of :func:`patchify` (the matrix is orthonormal: its transposed convolution inverts it)."""
    b, k = y.shape[0], patch_size**2 * patch_time
    coeffs = rearrange(y, "b (k c) t h w -> (b c t) k h w", k=k)
    frames = F.conv_transpose2d(coeffs, _haar_kernel(patch_size, patch_time, y), stride=patch_size)
    video = rearrange(frames, "(b c t) pt h w -> b c (t pt) h w", b=b, c=y.shape[1] // k)
    return video[:, :, patch_time - 1 :] if first_chunk else video


def _haar_kernel(patch_size: int, patch_time: int, like: torch.Tensor) -> torch.Tensor:
    """:func:`haar_matrix` as a conv2d weight (K, patch_time, patch_size, patch_size)."""
    m = haar_matrix(patch_size, patch_time, like.dtype, like.device)
    return m.view(-1, patch_time, patch_size, patch_size)


@functools.lru_cache(maxsize=16)
def haar_matrix(patch_size: int, patch_time: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """(K, K), K = patch_size^2 * patch_time: row j holds subband j of the nested Haar steps as weights of
    the patch's pixels ordered (t, y, x). Built by running the nested steps on the one-hot patches."""
    k = patch_size**2 * patch_time
    x = torch.eye(k, dtype=torch.float64).view(k, 1, patch_time, patch_size, patch_size)
    for _ in range(_levels(patch_size)):
        x = haar_space(x)
    for _ in range(_levels(patch_time)):
        x = haar_time(x, first_chunk=False)
    return x.view(k, k).T.contiguous().to(dtype=dtype, device=device)


def _levels(patch: int) -> int:
    return int(math.log2(patch))
