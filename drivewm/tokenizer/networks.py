"""Encoder and decoder of the causal video autoencoder (after the Haar patch, before the quantizer).

Encoder: conv_in -> per stage (resblocks, then downsample except at the last stage) -> mid
resblock -> norm/act -> conv_out to the latent channels. Time is downsampled at the first
``temporal_downs`` stages (earliest, where it saves the most compute). The decoder mirrors it.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from drivewm.tokenizer.causal import CausalContext
from drivewm.tokenizer.config import TokenizerConfig
from drivewm.tokenizer.layers import ChannelAverage, ChannelRMSNorm, Downsample, FactorizedConv, ResBlock, Upsample


def patch_channels(cfg: TokenizerConfig) -> int:
    """Channels after the Haar patch: 3 colours x 4 spatial subbands x (2 temporal subbands)."""
    return 3 * 4 * cfg.haar_time


def channel_shortcut(cin: int, cout: int) -> ChannelAverage | None:
    """DC-AE's parameter-free shortcut around a channel-changing layer, where the widths divide."""
    return ChannelAverage(cin, cout) if max(cin, cout) % min(cin, cout) == 0 else None


def with_shortcut(y: torch.Tensor, shortcut: ChannelAverage | None, x: torch.Tensor) -> torch.Tensor:
    return y if shortcut is None else y + shortcut(x)


class Encoder(nn.Module):
    """(B, patch_channels, T', H', W') Haar coefficients -> (B, c, t, h, w) unquantized latents."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        widths = [cfg.base_channels * m for m in cfg.channel_multipliers]
        kt = cfg.temporal_kernel
        self.conv_in = FactorizedConv(patch_channels(cfg), widths[0], kt)
        self.shortcut_in = channel_shortcut(patch_channels(cfg), widths[0])
        self.blocks = nn.ModuleList()
        cin = widths[0]
        for i, width in enumerate(widths):
            for _ in range(cfg.num_res_blocks):
                self.blocks.append(ResBlock(cin, width, kt))
                cin = width
            if i < cfg.spatial_downs:
                self.blocks.append(Downsample(width, temporal=i < cfg.temporal_downs))
        self.mid = ResBlock(cin, cin, kt)
        self.norm_out = ChannelRMSNorm(cin)
        self.conv_out = FactorizedConv(cin, cfg.code_channels, kt)
        self.shortcut_out = channel_shortcut(cin, cfg.code_channels)

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = with_shortcut(self.conv_in(x, ctx), self.shortcut_in, x)  # (B, C0, T', H', W')
        for block in self.blocks:
            h = block(h, ctx)  # resolution halves at each Downsample
        h = self.mid(h, ctx)  # (B, C_last, t, h, w)
        return with_shortcut(self.conv_out(F.silu(self.norm_out(h)), ctx), self.shortcut_out, h)  # (B, c, t, h, w)


class Decoder(nn.Module):
    """(B, c, t, h, w) latents -> (B, patch_channels, T', H', W') Haar coefficients."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        widths = [cfg.base_channels * m for m in cfg.channel_multipliers]
        kt = cfg.temporal_kernel
        self.conv_in = FactorizedConv(cfg.code_channels, widths[-1], kt)
        self.shortcut_in = channel_shortcut(cfg.code_channels, widths[-1])
        self.mid = ResBlock(widths[-1], widths[-1], kt)
        self.blocks = nn.ModuleList()
        cin = widths[-1]
        for i in reversed(range(len(widths))):
            for _ in range(cfg.num_res_blocks):
                self.blocks.append(ResBlock(cin, widths[i], kt))
                cin = widths[i]
            if i > 0:
                self.blocks.append(Upsample(cin, temporal=i - 1 < cfg.temporal_downs))
        self.norm_out = ChannelRMSNorm(cin)
        self.conv_out = FactorizedConv(cin, patch_channels(cfg), kt)
        self.shortcut_out = channel_shortcut(cin, patch_channels(cfg))

    def forward(self, z: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.mid(with_shortcut(self.conv_in(z, ctx), self.shortcut_in, z), ctx)  # (B, C_last, t, h, w)
        for block in self.blocks:
            h = block(h, ctx)  # resolution doubles at each Upsample
        return with_shortcut(self.conv_out(F.silu(self.norm_out(h)), ctx), self.shortcut_out, h)  # (B, patch_channels, T', H', W')
