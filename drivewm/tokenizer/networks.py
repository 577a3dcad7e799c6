"""Encoder and decoder of the causal video autoencoder (after the Haar patch, before the quantizer).

Encoder: a pointwise projection of the Haar patch -> per stage (resblocks, then downsample except
at the last stage) -> ``encoder_mid_blocks`` resblocks -> norm/act -> conv to the latent channels. Time is
downsampled at the first ``temporal_downs`` stages (earliest, where it saves the most compute).
The decoder mirrors it and ends in a pointwise head onto the Haar patch. Capacity sits where the
resolution is lowest (the mid blocks at the bottleneck), which buys parameters for few FLOPs.
"""

from __future__ import annotations

import torch
from torch import nn

from drivewm.tokenizer.causal import CausalContext
from drivewm.tokenizer.config import TokenizerConfig
from drivewm.tokenizer.layers import Downsample, FactorizedConv, OutputHead, PatchProjection, ResBlock, Upsample


class Encoder(nn.Module):
    """(B, patch_channels, T', H', W') Haar coefficients -> (B, c, t, h, w) unquantized latents."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        widths = [cfg.base_channels * m for m in cfg.channel_multipliers]
        kt = cfg.temporal_kernel
        self.conv_in = PatchProjection(cfg.patch_channels, widths[0])
        self.blocks = nn.ModuleList()
        cin = widths[0]
        for i, width in enumerate(widths):
            for _ in range(cfg.num_res_blocks):
                self.blocks.append(ResBlock(cin, width, kt))
                cin = width
            if i < cfg.spatial_downs:
                self.blocks.append(Downsample(width, temporal=i < cfg.temporal_downs))
        self.mid = nn.ModuleList(ResBlock(cin, cin, kt) for _ in range(cfg.encoder_mid_blocks))
        self.head = OutputHead(cin, cfg.code_channels, kt)

    def forward(self, x: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.conv_in(x, ctx)  # (B, C0, T', H', W')
        for block in self.blocks:
            h = block(h, ctx)  # resolution halves at each Downsample
        for block in self.mid:
            h = block(h, ctx)  # (B, C_last, t, h, w)
        return self.head(h, ctx)  # (B, c, t, h, w)


class Decoder(nn.Module):
    """(B, c, t, h, w) latents -> (B, patch_channels, T', H', W') Haar coefficients."""

    def __init__(self, cfg: TokenizerConfig):
        super().__init__()
        widths = [cfg.base_channels * m for m in cfg.channel_multipliers]
        kt = cfg.temporal_kernel
        self.conv_in = FactorizedConv(cfg.code_channels, widths[-1], kt, identity=True)
        self.mid = nn.ModuleList(ResBlock(widths[-1], widths[-1], kt) for _ in range(cfg.decoder_mid_blocks))
        self.blocks = nn.ModuleList()
        cin = widths[-1]
        for i in reversed(range(len(widths))):
            for j in range(cfg.num_res_blocks):
                # the stage's last block already narrows to the next stage's width, so the upsampling
                # and everything after it run at the narrow width (the encoder widens after downsampling)
                cout = widths[i - 1] if i > 0 and j == cfg.num_res_blocks - 1 else widths[i]
                self.blocks.append(ResBlock(cin, cout, kt))
                cin = cout
            if i > 0:
                self.blocks.append(Upsample(cin, temporal=i - 1 < cfg.temporal_downs))
        self.head = OutputHead(cin, cfg.patch_channels, kt, pointwise=True)

    def forward(self, z: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        h = self.conv_in(z, ctx)  # (B, C_last, t, h, w)
        for block in [*self.mid, *self.blocks]:
            h = block(h, ctx)  # resolution doubles at each Upsample
        return self.head(h, ctx)  # (B, patch_channels, T', H', W')
