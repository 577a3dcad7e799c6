"""Tokenizer configuration and named presets (DESIGN.md section 5).

A preset name reads ``SIZE-TxHxW[-fsq]``: ``debug-4x8x8`` compresses 4x in time and 8x in
height and width into 16 continuous channels; ``base-8x8x8-fsq`` quantizes with FSQ instead.
``debug``, ``small`` and ``base`` alone mean their ``-4x8x8`` continuous variant.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Literal

from drivewm.config import at_least, require
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class TokenizerConfig:
    """The network that :class:`drivewm.tokenizer.Tokenizer` builds."""

    base_channels: int = 32
    """Channels of the first (highest-resolution) stage."""
    channel_multipliers: list[int] = dataclasses.field(default_factory=lambda: [1, 2, 4])
    """Per-stage channel multiplier; one stage per spatial resolution after the Haar patch
    (so ``len == log2(spatial_compression / 2) + 1``)."""
    num_res_blocks: int = 1
    """Residual blocks per stage (encoder and decoder alike)."""
    spatial_compression: int = 8
    """Height and width downsampling factor (4, 8 or 16). The 2x2 Haar patch gives 2x."""
    temporal_compression: int = 4
    """Time downsampling factor f (1, 2, 4 or 8): T = 1 + k*f frames give 1 + k latent frames."""
    temporal_haar: bool = True
    """Also apply the causal temporal Haar step at the input (2x of the time compression)."""
    temporal_kernel: int = 3
    """Kernel length of the causal temporal convolutions."""
    latent_channels: int = 16
    """Channels of continuous latents (ignored by FSQ: there the channels are ``len(fsq_levels)``)."""
    quantizer: Literal["continuous", "fsq"] = "continuous"
    """``continuous`` latents or finite scalar quantization (Mentzer et al. 2023, arXiv 2309.15505)."""
    fsq_levels: list[int] = dataclasses.field(default_factory=lambda: [8, 8, 8, 5, 5, 5])
    """FSQ levels per latent channel; the codebook has ``prod(fsq_levels)`` codes."""

    @property
    def code_channels(self) -> int:
        """Channels c of the latents (B, c, t, h, w)."""
        return len(self.fsq_levels) if self.quantizer == "fsq" else self.latent_channels

    @property
    def haar_time(self) -> int:
        return 2 if self.temporal_haar and self.temporal_compression > 1 else 1

    @property
    def spatial_downs(self) -> int:
        return int(math.log2(self.spatial_compression // 2))

    @property
    def temporal_downs(self) -> int:
        return int(math.log2(self.temporal_compression // self.haar_time))

    def validate(self) -> None:
        if self.spatial_compression not in (4, 8, 16):
            raise DrivewmError(
                f"tokenizer config: spatial_compression must be 4, 8 or 16, got {self.spatial_compression}"
            )
        if self.temporal_compression not in (1, 2, 4, 8):
            raise DrivewmError(
                f"tokenizer config: temporal_compression must be 1, 2, 4 or 8, got {self.temporal_compression}"
            )
        if len(self.channel_multipliers) != self.spatial_downs + 1:
            raise DrivewmError(
                f"tokenizer config: channel_multipliers needs {self.spatial_downs + 1} entries for spatial_compression "
                f"{self.spatial_compression}, got {self.channel_multipliers}"
            )
        if self.temporal_downs > self.spatial_downs:
            raise DrivewmError("tokenizer config: more temporal than spatial downsampling steps is not supported")
        if self.quantizer == "fsq" and (not self.fsq_levels or min(self.fsq_levels) < 2):
            raise DrivewmError(f"tokenizer config: fsq_levels must be integers >= 2, got {self.fsq_levels}")
        at_least(self, 1, "base_channels", "temporal_kernel", "latent_channels")
        at_least(self, 0, "num_res_blocks")
        require(min(self.channel_multipliers) >= 1, "channel_multipliers", self.channel_multipliers, "integers >= 1")


#: Network sizes; the compression and quantizer variants are derived from these.
SIZES: dict[str, dict] = {
    "debug": dict(base_channels=16, channel_multipliers=[1, 2, 2], num_res_blocks=1),  # ~0.2M params, CPU in a minute
    "small": dict(base_channels=64, channel_multipliers=[1, 2, 4], num_res_blocks=2),  # ~10M, one GPU
    "base": dict(base_channels=128, channel_multipliers=[1, 2, 4], num_res_blocks=2),  # ~40M, GPU
}
#: Compression variants: name -> (temporal, spatial).
COMPRESSIONS = {"4x8x8": (4, 8), "8x8x8": (8, 8), "8x16x16": (8, 16), "1x8x8": (1, 8)}
#: Default FSQ levels per size (codebook 1,000 for debug, 64,000 otherwise as in Cosmos DV).
FSQ_LEVELS = {"debug": [8, 5, 5, 5], "small": [8, 8, 8, 5, 5, 5], "base": [8, 8, 8, 5, 5, 5]}


def _build_presets() -> dict[str, TokenizerConfig]:
    presets: dict[str, TokenizerConfig] = {}
    for size, fields in SIZES.items():
        for name, (temporal, spatial) in COMPRESSIONS.items():
            mults = list(fields["channel_multipliers"])
            mults = mults + [mults[-1]] * (int(math.log2(spatial // 2)) + 1 - len(mults))
            common = dict(fields, channel_multipliers=mults, temporal_compression=temporal, spatial_compression=spatial)
            presets[f"{size}-{name}"] = TokenizerConfig(**common)
            presets[f"{size}-{name}-fsq"] = TokenizerConfig(
                **common, quantizer="fsq", fsq_levels=list(FSQ_LEVELS[size])
            )
        presets[size] = presets[f"{size}-4x8x8"]
    return presets


PRESETS: dict[str, TokenizerConfig] = _build_presets()


def preset(name: str) -> TokenizerConfig:
    """A fresh copy of the named preset; an unknown name lists the known ones."""
    if name not in PRESETS:
        raise DrivewmError(f"unknown tokenizer preset {name!r}; known: {sorted(PRESETS)}")
    return copy.deepcopy(PRESETS[name])
