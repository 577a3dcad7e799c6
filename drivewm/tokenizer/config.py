"""Tokenizer configuration and presets (docs/DESIGN.md section 5).

A preset is a network size (:data:`SIZES`), a compression ``TxHxW`` (:data:`COMPRESSIONS`) and a
quantizer: ``preset("debug")`` compresses 4x in time and 8x in height and width into 16 continuous
channels; ``preset("base", "8x8x8", fsq=True)`` compresses 8x8x8 and quantizes with FSQ instead
(``drivewm tokenizer train --preset base --compression 8x8x8 --fsq``).
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
    channel_multipliers: list[int] = dataclasses.field(default_factory=lambda: [1, 2])
    """Per-stage channel multiplier; one stage per spatial resolution after the Haar patch
    (so ``len == log2(spatial_compression / patch_size) + 1``)."""
    num_res_blocks: int = 1
    """Residual blocks per stage (encoder and decoder alike)."""
    encoder_mid_blocks: int = 1
    """Residual blocks of the encoder at the bottleneck resolution, where parameters cost the fewest FLOPs."""
    decoder_mid_blocks: int = 2
    """Residual blocks of the decoder at the bottleneck resolution. The decoder gets more than the
    encoder (as in Cosmos' and most video VAEs' decoders): it must synthesize the detail the latents drop."""
    spatial_compression: int = 8
    """Height and width downsampling factor (4, 8 or 16)."""
    temporal_compression: int = 4
    """Time downsampling factor f (1, 2, 4 or 8): T = 1 + k*f frames give 1 + k latent frames."""
    patch_size: int = 4
    """Spatial Haar patch (2, 4 or 8: one, two or three levels of the 2x2 Haar transform): the network
    starts at 1/patch_size of the resolution, where convolutions cost patch_size^2 times less
    (Cosmos Tokenizer uses 4). The rest of ``spatial_compression`` is learned downsampling."""
    patch_time: int = 4
    """Temporal causal Haar patch (1, 2 or 4, at most ``temporal_compression``); the rest of the time
    compression is learned downsampling."""
    temporal_kernel: int = 3
    """Kernel length of the causal temporal convolutions."""
    latent_channels: int = 16
    """Channels of continuous latents (ignored by FSQ: there the channels are ``len(fsq_levels)``)."""
    quantizer: Literal["continuous", "fsq"] = "continuous"
    """``continuous`` latents or finite scalar quantization (Mentzer et al. 2023, arXiv 2309.15505)."""
    fsq_levels: list[int] = dataclasses.field(default_factory=lambda: [8, 8, 8, 5, 5, 5])
    """FSQ levels per latent channel; the codebook has ``prod(fsq_levels)`` codes."""
    linear_code: Literal["none", "pca"] = "none"
    """``pca``: a linear code path beside the networks, fitted to the principal components of the
    training blocks before step 0, with the networks learning only the rest (drivewm.tokenizer.linear_code);
    continuous latents only."""

    @property
    def code_channels(self) -> int:
        """Channels c of the latents (B, c, t, h, w)."""
        return len(self.fsq_levels) if self.quantizer == "fsq" else self.latent_channels

    @property
    def patch_channels(self) -> int:
        """Channels after the Haar patch: 3 colours x patch_size^2 spatial x patch_time temporal subbands."""
        return 3 * self.patch_size**2 * self.patch_time

    @property
    def spatial_downs(self) -> int:
        """Learned 2x spatial downsampling steps after the patch."""
        return int(math.log2(self.spatial_compression // self.patch_size))

    @property
    def temporal_downs(self) -> int:
        """Learned 2x temporal downsampling steps after the patch."""
        return int(math.log2(self.temporal_compression // self.patch_time))

    def validate(self) -> None:
        if self.spatial_compression not in (4, 8, 16):
            raise DrivewmError(
                f"tokenizer config: spatial_compression must be 4, 8 or 16, got {self.spatial_compression}"
            )
        if self.temporal_compression not in (1, 2, 4, 8):
            raise DrivewmError(
                f"tokenizer config: temporal_compression must be 1, 2, 4 or 8, got {self.temporal_compression}"
            )
        if self.patch_size not in (2, 4, 8) or self.patch_size > self.spatial_compression:
            raise DrivewmError(
                f"tokenizer config: patch_size must be 2, 4 or 8 and at most spatial_compression, got {self.patch_size}"
            )
        if self.patch_time not in (1, 2, 4) or self.patch_time > self.temporal_compression:
            raise DrivewmError(
                f"tokenizer config: patch_time must be 1, 2 or 4 and at most temporal_compression, "
                f"got {self.patch_time}"
            )
        if len(self.channel_multipliers) != self.spatial_downs + 1:
            raise DrivewmError(
                f"tokenizer config: channel_multipliers needs {self.spatial_downs + 1} entries for spatial_compression "
                f"{self.spatial_compression}, got {self.channel_multipliers}"
            )
        if self.temporal_downs > self.spatial_downs:
            raise DrivewmError("tokenizer config: more temporal than spatial downsampling steps is not supported")
        if self.linear_code == "pca" and self.quantizer != "continuous":
            raise DrivewmError("tokenizer config: linear_code=pca needs continuous latents (FSQ would clip the code)")
        if self.quantizer == "fsq" and (not self.fsq_levels or min(self.fsq_levels) < 2):
            raise DrivewmError(f"tokenizer config: fsq_levels must be integers >= 2, got {self.fsq_levels}")
        at_least(self, 1, "base_channels", "temporal_kernel", "latent_channels")
        at_least(self, 0, "num_res_blocks", "encoder_mid_blocks", "decoder_mid_blocks")
        require(min(self.channel_multipliers) >= 1, "channel_multipliers", self.channel_multipliers, "integers >= 1")


@dataclasses.dataclass
class LossConfig:
    """Weights of the loss terms."""

    l1: float = 1.0
    """Pixel L1."""
    ssim: float = 0.2
    """Structural term ``1 - SSIM`` (keeps lane markings and edges sharp)."""
    temporal: float = 0.5
    """L1 between the frame differences of reconstruction and input (penalizes flicker)."""
    perceptual: float = 0.0
    """VGG16 feature distance; > 0 needs ``perceptual_weights``."""
    perceptual_weights: str = ""
    """Local VGG16 state dict (.safetensors, or a .pth read with weights_only=True), torchvision key names."""
    adversarial: float = 0.0
    """Weight of the hinge-GAN generator term (a PatchGAN discriminator trains alongside; 0 = off)."""
    adversarial_start: int = 0
    """Step from which the adversarial terms run (after the reconstruction has settled)."""
    discriminator_weights: str = ""
    """Optional local discriminator state dict (.safetensors) to start from; empty = from scratch."""

    def validate(self) -> None:
        at_least(self, 0, "l1", "ssim", "temporal", "perceptual", "adversarial", "adversarial_start")
        if self.perceptual > 0 and not self.perceptual_weights:
            raise DrivewmError(
                "loss.perceptual > 0 needs loss.perceptual_weights: a local VGG16 state dict "
                "(.safetensors or .pth); drivewm never downloads weights"
            )


#: Network sizes; the compression and quantizer are the other two axes of a preset.
#: Parameter counts at 8x8x8 (continuous); Cosmos-architecture peers of matched size are in
#: benchmarks/bench_tokenizer.py (tiny ~ diffusers AutoencoderKLCosmos at (32, 64, 64, 64), 1.75M;
#: small ~ (32, 64, 128, 128), 5.1M).
SIZES: dict[str, dict] = {
    "debug": dict(base_channels=16, channel_multipliers=[1, 2], decoder_mid_blocks=1),  # 0.12M, for tests
    "tiny": dict(base_channels=48, channel_multipliers=[1, 2], decoder_mid_blocks=3),  # 1.4M
    "small": dict(base_channels=48, channel_multipliers=[1, 4], decoder_mid_blocks=3),  # 4.7M
    "base": dict(
        base_channels=96, channel_multipliers=[1, 4], num_res_blocks=2, encoder_mid_blocks=2, decoder_mid_blocks=4
    ),
}
#: Compressions ``TxHxW`` -> (temporal, spatial); the first is the default.
COMPRESSIONS = {"4x8x8": (4, 8), "8x8x8": (8, 8), "8x16x16": (8, 16), "1x8x8": (1, 8)}
DEFAULT_COMPRESSION = "4x8x8"
#: Default FSQ levels per size (codebook 1,000 for debug, 64,000 otherwise as in Cosmos DV).
FSQ_LEVELS = {
    "debug": [8, 5, 5, 5],
    "tiny": [8, 8, 8, 5, 5, 5],
    "small": [8, 8, 8, 5, 5, 5],
    "base": [8, 8, 8, 5, 5, 5],
}


def compression_fields(size: str, compression: str) -> dict:
    """The TokenizerConfig fields that ``compression`` (``TxHxW``) sets for ``size``: the two factors,
    the temporal Haar patch (at most 4) and one channel multiplier per spatial stage (the size's last
    repeated for a deeper downsampling)."""
    temporal, spatial = COMPRESSIONS[compression]
    mults = list(SIZES[size]["channel_multipliers"])
    mults += [mults[-1]] * (int(math.log2(spatial // 4)) + 1 - len(mults))
    return dict(
        channel_multipliers=mults,
        temporal_compression=temporal,
        spatial_compression=spatial,
        patch_size=4,
        patch_time=min(4, temporal),
    )


def fsq_fields(size: str) -> dict:
    """The TokenizerConfig fields of FSQ latents for ``size``."""
    return dict(quantizer="fsq", fsq_levels=list(FSQ_LEVELS[size]))


def preset(size: str, compression: str = DEFAULT_COMPRESSION, fsq: bool = False) -> TokenizerConfig:
    """A fresh TokenizerConfig of network ``size`` at ``compression`` (``TxHxW``), FSQ-quantized
    when ``fsq``; an unknown size or compression lists the known ones."""
    if size not in SIZES:
        raise DrivewmError(f"unknown tokenizer size {size!r}; known: {list(SIZES)}")
    if compression not in COMPRESSIONS:
        raise DrivewmError(f"unknown tokenizer compression {compression!r}; known: {list(COMPRESSIONS)}")
    fields = {**copy.deepcopy(SIZES[size]), **compression_fields(size, compression)}
    return TokenizerConfig(**fields, **(fsq_fields(size) if fsq else {}))
