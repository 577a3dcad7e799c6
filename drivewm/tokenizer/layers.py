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


def conv_per_frame(conv: nn.Conv3d, x: torch.Tensor, stride: int = 1, padding: int = 0) -> torch.Tensor:
    """A (1, k, k) ``Conv3d`` applied to every frame of ``x`` (B, C, T, H, W) as one 2D convolution
    over the frames folded into the batch: the same weights and result, 3-7x faster than
    ``Conv3d`` on CPUs (measured in benchmarks/bench_tokenizer.py's profile)."""
    frames = rearrange(x, "b c t h w -> (b t) c h w")
    y = F.conv2d(frames, conv.weight[:, :, 0], conv.bias, stride, padding)  # (B T, C', H', W')
    return rearrange(y, "(b t) c h w -> b c t h w", b=x.shape[0])


def conv_pointwise(conv: nn.Conv3d, x: torch.Tensor) -> torch.Tensor:
    """A 1x1x1 ``Conv3d`` on ``x`` (B, C, T, H, W) as a 2D convolution over (T, H*W): same result, faster."""
    y = F.conv2d(x.flatten(3), conv.weight[..., 0], conv.bias)  # (B, C', T, H*W)
    return y.view(y.shape[0], y.shape[1], *x.shape[2:])


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
        return self.temporal(conv_per_frame(self.spatial, x, padding=1), ctx)


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

    def start_as_identity(self) -> None:
        """Zero the residual branch's last convolution, bias included, so a block with cin == cout
        returns its input exactly: a block added to a trained network leaves its output unchanged."""
        _zero_init(self.conv2.temporal.conv)

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.conv1(F.silu(self.norm1(x)), ctx)  # (B, Cout, T, H, W)
        h = self.conv2(F.silu(self.norm2(h)), ctx)
        return _skip(self.skip, x) + h


class OutputHead(nn.Module):
    """norm -> SiLU -> conv to ``cout`` channels, plus an identity-initialized 1x1 skip, so the head
    starts by passing its first ``cout`` input channels through. The conv is factorized (3x3 then
    causal temporal) at the bottleneck, or ``pointwise`` where the head writes the Haar patch: there,
    at the highest resolution the network sees, a 3x3 or temporal conv onto 3 * 4^2 * 4 = 192
    wavelet channels would cost as much as a whole residual block, and the block before it has
    already mixed space and time."""

    def __init__(self, cin: int, cout: int, temporal_kernel: int, pointwise: bool = False):
        super().__init__()
        self.norm = ChannelRMSNorm(cin)
        self.conv = nn.Conv3d(cin, cout, 1) if pointwise else FactorizedConv(cin, cout, temporal_kernel)
        self.skip = nn.Conv3d(cin, cout, 1)
        _zero_init(self.conv if pointwise else self.conv.temporal.conv)
        _identity_init(self.skip, tap=(0, 0, 0))

    def silence(self) -> None:
        """Output zero (skip included) until trained: for a head that adds to another path."""
        _zero_init(self.skip, self.conv if isinstance(self.conv, nn.Conv3d) else self.conv.temporal.conv)

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = F.silu(self.norm(x))
        h = conv_pointwise(self.conv, h) if isinstance(self.conv, nn.Conv3d) else self.conv(h, ctx)
        return conv_pointwise(self.skip, x) + h


class PatchProjection(nn.Module):
    """Identity-initialized 1x1 projection of the Haar patch channels (the first ``cout`` pass through).

    The Haar patch already gathers each patch_size^2 x patch_time block into channels, so a
    pointwise projection suffices here (DC-AE's space-to-channel input, Chen et al. 2024); the
    residual blocks that follow mix neighbouring patches in space and time."""

    def __init__(self, cin: int, cout: int):
        super().__init__()
        self.proj = nn.Conv3d(cin, cout, 1)
        _identity_init(self.proj, tap=(0, 0, 0))

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        return conv_pointwise(self.proj, x)


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
        x = conv_per_frame(self.spatial, F.pad(x, (0, 1, 0, 1)), stride=2) + shortcut
        if self.temporal is None:
            return x
        if is_first(ctx):
            x = torch.cat([x[:, :, :1], x], dim=2)
        pairs = rearrange(x, "b c (t two) h w -> b (two c) t h w", two=2)  # (B, 2C, T/2, H/2, W/2)
        return conv_pointwise(self.temporal, pairs) + (pairs[:, : x.shape[1]] + pairs[:, x.shape[1] :]) / 2


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
            x = conv_pointwise(self.temporal, x) + x.repeat(1, 2, 1, 1, 1)  # (B, 2C, T, H, W)
            x = rearrange(x, "b (two c) t h w -> b c (t two) h w", two=2)
            if is_first(ctx):
                x = x[:, :, 1:]  # latent frame 0 decodes to frame 0 alone
        x = x.repeat_interleave(2, dim=3).repeat_interleave(2, dim=4)  # nearest 2x in H and W
        return conv_per_frame(self.spatial, x, padding=1) + x


def _skip(skip: nn.Module, x: torch.Tensor) -> torch.Tensor:
    return conv_pointwise(skip, x) if isinstance(skip, nn.Conv3d) else x


def _zero_init(*convs: nn.Conv3d | None) -> None:
    for conv in convs:
        if conv is not None:
            nn.init.zeros_(conv.weight)
            if conv.bias is not None:
                nn.init.zeros_(conv.bias)


@torch.no_grad()
def _identity_init(conv: nn.Conv3d, tap: tuple[int, int, int]) -> None:
    """Weights that copy input channel i to output channel i at kernel position ``tap``."""
    conv.weight.zero_()
    conv.bias.zero_()
    for i in range(min(conv.in_channels, conv.out_channels)):
        conv.weight[i, i, tap[0], tap[1], tap[2]] = 1.0
