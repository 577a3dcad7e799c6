"""Building blocks of the causal video autoencoder: factorized convolutions, residual blocks, resamplers.

All layers take (B, C, T, H, W) and an optional :class:`CausalContext`. Spatial layers act on each
frame alone; temporal layers are causal (Cosmos Tokenizer's factorized design, arXiv 2501.03575
sec. 3.1: a 1xkxk spatial conv then a kx1x1 causal temporal conv). Normalization is per pixel
over channels (RMS), never over time or space, so a latent never depends on later frames and a
spatial tile sees the same statistics as the whole frame.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from drivewm.tokenizer.causal import CausalContext, causal_left_context, is_first


class ChannelRMSNorm(nn.Module):
    """RMS normalization over channels at every (t, y, x), with a learned per-channel gain."""

    def __init__(self, channels: int):
        super().__init__()
        self.scale = channels**0.5
        self.gain = nn.Parameter(torch.ones(channels, 1, 1, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.normalize(x, dim=1) * self.scale * self.gain


class CausalTemporalConv(nn.Module):
    """kx1x1 convolution over time; output frame t sees input frames t-k+1 .. t only."""

    def __init__(self, cin: int, cout: int, kernel: int):
        super().__init__()
        self.pad = kernel - 1
        self.conv = nn.Conv3d(cin, cout, (kernel, 1, 1))

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        x = causal_left_context(self, x, self.pad, ctx)  # (B, C, pad + T, H, W)
        # as a 2D conv over (time, pixels): several times faster than Conv3d on the CPU, same weights
        y = F.conv2d(rearrange(x, "b c t h w -> b c t (h w)"), self.conv.weight[..., 0], self.conv.bias)
        return rearrange(y, "b c t (h w) -> b c t h w", h=x.shape[-2])


class FactorizedConv(nn.Module):
    """1x3x3 spatial conv (each frame alone) followed by a causal kx1x1 temporal conv.

    ``identity=True`` starts it as the identity on the first min(cin, cout) channels (the others
    zero): with the zero-initialized residual branches and the averaging shortcuts of the
    resamplers, the untrained autoencoder is then a block-average codec rather than noise, which
    is what lets the CPU ``debug`` preset reach a useful PSNR in a few hundred steps.
    """

    def __init__(self, cin: int, cout: int, temporal_kernel: int, identity: bool = False):
        super().__init__()
        self.spatial = nn.Conv3d(cin, cout, (1, 3, 3), padding=(0, 1, 1))
        self.temporal = CausalTemporalConv(cout, cout, temporal_kernel)
        if identity:
            _identity_init(self.spatial, tap=(0, 1, 1))
            _identity_init(self.temporal.conv, tap=(temporal_kernel - 1, 0, 0))  # the current frame: causal

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        return self.temporal(self.spatial(x), ctx)


class ResBlock(nn.Module):
    """Pre-norm residual block of two factorized convolutions."""

    def __init__(self, cin: int, cout: int, temporal_kernel: int):
        super().__init__()
        self.norm1 = ChannelRMSNorm(cin)
        self.conv1 = FactorizedConv(cin, cout, temporal_kernel)
        self.norm2 = ChannelRMSNorm(cout)
        self.conv2 = FactorizedConv(cout, cout, temporal_kernel)
        self.skip = nn.Conv3d(cin, cout, 1) if cin != cout else nn.Identity()
        if cin != cout:
            _identity_init(self.skip, tap=(0, 0, 0))
        nn.init.zeros_(self.conv2.temporal.conv.weight)  # start as identity: stable training from step 0

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.conv1(F.silu(self.norm1(x)), ctx)  # (B, Cout, T, H, W)
        h = self.conv2(F.silu(self.norm2(h)), ctx)
        return self.skip(x) + h


class OutputHead(nn.Module):
    """norm -> SiLU -> factorized conv to ``cout`` channels, plus an identity-initialized 1x1
    skip, so the head starts by passing its first ``cout`` input channels through."""

    def __init__(self, cin: int, cout: int, temporal_kernel: int):
        super().__init__()
        self.norm = ChannelRMSNorm(cin)
        self.conv = FactorizedConv(cin, cout, temporal_kernel)
        self.skip = nn.Conv3d(cin, cout, 1)
        nn.init.zeros_(self.conv.temporal.conv.weight)
        _identity_init(self.skip, tap=(0, 0, 0))

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        return self.skip(x) + self.conv(F.silu(self.norm(x)), ctx)


class Downsample(nn.Module):
    """Halve H and W (strided 3x3 conv), and T when ``temporal`` (causal frame pairing).

    In time, a first chunk keeps frame 0 alone by pairing it with itself (T = 1+2k -> 1+k);
    a continuation chunk pairs its frames as they come (T = 2k -> k). The learned path is added
    to a parameter-free shortcut (average over the merged pixels and frames): the "residual
    autoencoding" of DC-AE (Chen et al. 2024, arXiv 2410.10733, sec. 3.2), which makes high
    compression train much faster.
    """

    def __init__(self, channels: int, temporal: bool):
        super().__init__()
        self.spatial = nn.Conv3d(channels, channels, (1, 3, 3), stride=(1, 2, 2))
        self.temporal = nn.Conv3d(2 * channels, channels, 1) if temporal else None
        _zero_init(self.spatial, self.temporal)  # start as the shortcut alone

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        shortcut = F.avg_pool3d(x, (1, 2, 2))  # (B, C, T, H/2, W/2)
        x = self.spatial(F.pad(x, (0, 1, 0, 1))) + shortcut
        if self.temporal is None:
            return x
        if is_first(ctx):
            x = torch.cat([x[:, :, :1], x], dim=2)
        pairs = rearrange(x, "b c (t two) h w -> b (two c) t h w", two=2)  # (B, 2C, T/2, H/2, W/2)
        return self.temporal(pairs) + (pairs[:, : x.shape[1]] + pairs[:, x.shape[1] :]) / 2


class Upsample(nn.Module):
    """Double H and W (nearest + 3x3 conv), and T when ``temporal`` (the mirror of :class:`Downsample`,
    with the repeating shortcut of DC-AE)."""

    def __init__(self, channels: int, temporal: bool):
        super().__init__()
        self.spatial = nn.Conv3d(channels, channels, (1, 3, 3), padding=(0, 1, 1))
        self.temporal = nn.Conv3d(channels, 2 * channels, 1) if temporal else None
        _zero_init(self.spatial, self.temporal)  # start as the shortcut alone

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        if self.temporal is not None:
            x = rearrange(self.temporal(x) + x.repeat(1, 2, 1, 1, 1), "b (two c) t h w -> b c (t two) h w", two=2)
            if is_first(ctx):
                x = x[:, :, 1:]  # latent frame 0 decodes to frame 0 alone
        x = F.interpolate(x, scale_factor=(1.0, 2.0, 2.0), mode="nearest")
        return self.spatial(x) + x


def _zero_init(*convs: nn.Conv3d | None) -> None:
    for conv in convs:
        if conv is not None:
            nn.init.zeros_(conv.weight)
            nn.init.zeros_(conv.bias)


@torch.no_grad()
def _identity_init(conv: nn.Conv3d, tap: tuple[int, int, int]) -> None:
    """Weights that copy input channel i to output channel i at kernel position ``tap``."""
    conv.weight.zero_()
    conv.bias.zero_()
    for i in range(min(conv.in_channels, conv.out_channels)):
        conv.weight[i, i, tap[0], tap[1], tap[2]] = 1.0
