"""The tokenizer's run config and its RecipeBook (drivewm.recipe): model / loss / data / train, nested
like every other stage's. ``--preset`` names the network size; the compression (``--compression
TxHxW``) and the quantizer (``--fsq``) are the book's two preset axes. No heavy imports, so
``drivewm tokenizer train --help`` lists the presets fast."""

from __future__ import annotations

import dataclasses

from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.recipe import PresetAxis, RecipeBook
from drivewm.tokenizer.config import (
    COMPRESSIONS,
    DEFAULT_COMPRESSION,
    SIZES,
    LossConfig,
    TokenizerConfig,
    compression_fields,
    fsq_fields,
    preset,
)
from drivewm.train.config import TrainConfig


@dataclasses.dataclass
class TokenizerDataConfig:
    """What one training sample is."""

    frames: int = 9
    """Frames per training video, 1 + k * temporal_compression."""
    crop: list[int] = dataclasses.field(default_factory=lambda: [64, 96])
    """Random crop [height, width] in pixels, multiples of the spatial compression."""
    holdout_percent: int = 10
    """Clips held out from training by key hash (``drivewm tokenizer eval --split holdout`` scores them)."""
    stats_batches: int = 4
    """Batches of ``train.batch_size`` crops encoded at each checkpoint to measure the latent mean and std."""
    linear_fit_batches: int = 32
    """Batches of ``train.batch_size`` crops whose blocks the linear code (``model.linear_code=pca``) is fitted to."""

    def validate(self) -> None:
        if self.frames < 1 or len(self.crop) != 2 or min(self.crop) < 1:
            raise DrivewmError(f"tokenizer data: frames must be >= 1 and crop [height, width] > 0, got {self.crop}")
        if not 0 <= self.holdout_percent < 100 or self.stats_batches < 1 or self.linear_fit_batches < 1:
            raise DrivewmError(
                "tokenizer data: holdout_percent must be in [0, 100), stats_batches and linear_fit_batches >= 1"
            )


@dataclasses.dataclass
class TokenizerTrainConfig:
    """A resolved tokenizer training run (printed by --dry-run, saved in train_state.pt)."""

    preset: str = "debug"
    """The network size the run started from (drivewm.tokenizer.config.SIZES); the model fields
    record its compression and quantizer."""
    model: TokenizerConfig = dataclasses.field(default_factory=TokenizerConfig)
    """The network."""
    loss: LossConfig = dataclasses.field(default_factory=LossConfig)
    """Loss weights (and the optional adversarial term)."""
    data: TokenizerDataConfig = dataclasses.field(default_factory=TokenizerDataConfig)
    """Training crops."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Optimisation and run settings (the shared loop's); ``batch_size`` counts crops."""
    init: str | None = None
    """Tokenizer folder whose weights start the run (same model config); None = the identity-like init."""
    freeze_encoder: bool = False
    """Train the decoder alone (with ``init``): the latent space, and every latent cache and diffusion
    model made with it, stay valid while the reconstructions sharpen (decoder fine-tuning)."""

    def validate(self) -> None:
        if self.freeze_encoder and not self.init:
            raise DrivewmError("tokenizer train: freeze_encoder needs init (the tokenizer whose encoder stays)")
        f, s = self.model.temporal_compression, self.model.spatial_compression
        if (self.data.frames - 1) % f:
            raise DrivewmError(f"tokenizer train: data.frames={self.data.frames} must be 1 + k*{f} for this model")
        if self.data.crop[0] % s or self.data.crop[1] % s:
            raise DrivewmError(f"tokenizer train: data.crop {self.data.crop} must be multiples of {s}")


#: Training defaults per network size.
TRAIN_DEFAULTS: dict[str, dict] = {
    "debug": dict(steps=300, batch_size=4, lr=3e-3, warmup_steps=20, ema_decay=0.99, checkpoint_every=100),
    "tiny": dict(steps=20000, batch_size=8, lr=5e-4, warmup_steps=200, ema_decay=0.999, checkpoint_every=500),
    "small": dict(steps=50000, batch_size=8, lr=3e-4, warmup_steps=500, ema_decay=0.999, checkpoint_every=1000),
    "base": dict(steps=100000, batch_size=16, lr=2e-4, warmup_steps=1000, ema_decay=0.999, checkpoint_every=2000),
}


def _with_compression(size: str, fields: dict, compression: str) -> dict:
    """A size's fields at ``compression``: the model's factors and stages, and training clips of two
    latent steps after the first frame (``data.frames = 1 + 2T``)."""
    model = {**fields["model"], **compression_fields(size, compression)}
    data = {**fields.get("data", {}), "frames": 1 + 2 * model["temporal_compression"]}
    return {**fields, "model": model, "data": data}


def _with_fsq(size: str, fields: dict, fsq: bool) -> dict:
    """A size's fields with FSQ latents (the size's default levels) when ``fsq``."""
    return {**fields, "model": {**fields["model"], **fsq_fields(size)}} if fsq else fields


#: The preset axes beside the size (drivewm.recipe.PresetAxis).
AXES = (
    PresetAxis(
        "compression",
        DEFAULT_COMPRESSION,
        _with_compression,
        "compression in time x height x width",
        tuple(COMPRESSIONS),
        "TxHxW",
    ),
    PresetAxis("fsq", False, _with_fsq, "finite scalar quantization (FSQ) latents instead of continuous ones"),
)

RECIPES: RecipeBook[TokenizerTrainConfig] = RecipeBook(
    "tokenizer train",
    TokenizerTrainConfig,
    {size: {"model": to_dict(preset(size)), "train": dict(TRAIN_DEFAULTS[size])} for size in SIZES},
    "debug",
    axes=AXES,
)
