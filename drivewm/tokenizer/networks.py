"""Encoder and decoder of the causal video autoencoder (after the Haar patch, before the quantizer).

Encoder: conv_in -> per stage (resblocks, then downsample except at the last stage) -> mid
resblock -> norm/act -> conv_out to the latent channels. Time is downsampled at the first
``temporal_downs`` stages (earliest, where it saves the most compute). The decoder mirrors it.
"""

from __future__ import annotations

import torch
from torch import nn

from drivewm.tokenizer.causal import CausalContext
from drivewm.tokenizer.config import TokenizerConfig
from drivewm.tokenizer.layers import Downsample, FactorizedConv, OutputHead, ResBlock, Upsample


def patch_channels(cfg: TokenizerConfig) -> int:
    """Channels after the Haar patch: 3 colours x 4 spatial subbands x (2 temporal subbands)."""
    return 3 * 4 * cfg.haar_time


class Encoder(nn.Module):
    """(B, patch_channels, T', H', W') Haar coefficients -> (B, c, t, h, w) unquantized latents."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        widths = [cfg.base_channels * m for m in cfg.channel_multipliers]
        kt = cfg.temporal_kernel
        self.conv_in = FactorizedConv(patch_channels(cfg), widths[0], kt, identity=True)
        self.blocks = nn.ModuleList()
        cin = widths[0]
        for i, width in enumerate(widths):
            for _ in range(cfg.num_res_blocks):
                self.blocks.append(ResBlock(cin, width, kt))
                cin = width
            if i < cfg.spatial_downs:
                self.blocks.append(Downsample(width, temporal=i < cfg.temporal_downs))
        self.mid = ResBlock(cin, cin, kt)
        self.head = OutputHead(cin, cfg.code_channels, kt)

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.conv_in(x, ctx)  # (B, C0, T', H', W')
        for block in self.blocks:
            h = block(h, ctx)  # resolution halves at each Downsample
        h = self.mid(h, ctx)  # (B, C_last, t, h, w)
        return self.head(h, ctx)  # (B, c, t, h, w)


class Decoder(nn.Module):
    """(B, c, t, h, w) latents -> (B, patch_channels, T', H', W') Haar coefficients."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        widths = [cfg.base_channels * m for m in cfg.channel_multipliers]
        kt = cfg.temporal_kernel
        self.conv_in = FactorizedConv(cfg.code_channels, widths[-1], kt, identity=True)
        self.mid = ResBlock(widths[-1], widths[-1], kt)
        self.blocks = nn.ModuleList()
        cin = widths[-1]
        for i in reversed(range(len(widths))):
            for _ in range(cfg.num_res_blocks):
                self.blocks.append(ResBlock(cin, widths[i], kt))
                cin = widths[i]
            if i > 0:
                self.blocks.append(Upsample(cin, temporal=i - 1 < cfg.temporal_downs))
        self.head = OutputHead(cin, patch_channels(cfg), kt)

    def forward(self, z: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.mid(self.conv_in(z, ctx), ctx)  # (B, C_last, t, h, w)
        for block in self.blocks:
            h = block(h, ctx)  # resolution doubles at each Upsample
        return self.head(h, ctx)  # (B, patch_channels, T', H', W')
