"""Typed configs of the transfer model: the parent's networks plus what transfer adds."""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.diffusion.denoiser import EDMConfig
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.errors import DrivewmError
from drivewm.text import TextConfig


@dataclasses.dataclass
class TransferConfig:
    """How the transfer model sees the source clip and the target condition (new parameters start
    at zero effect, so the step-0 model is its Text2World parent)."""

    source: Literal["channels", "none"] = "channels"
    """``channels``: the source clip's (normalised) latents, with a given-mask channel, patchified like
    the DiT input and added to its patch tokens by a zero-initialised projection (the same as extra
    input channels with zero-initialised patch-embedding columns). ``none``: the parent alone (ablation)."""
    condition_fields: bool = True
    """Also condition on the target weather and time of day as structured fields (GAIA-2 style): learned
    embeddings through a zero-initialised MLP added to the timestep embedding."""
    condition_width: int = 64
    """Width of the weather / time-of-day embeddings."""
    condition_dropout: float = 0.1
    """Training: probability of dropping a sample's target condition (caption and fields together), the
    unconditional branch of classifier-free guidance; the source is always kept."""

    def validate(self) -> None:
        if self.condition_width < 1 or not 0 <= self.condition_dropout < 1:
            raise DrivewmError("transfer: condition_width must be >= 1 and 0 <= condition_dropout < 1")


@dataclasses.dataclass
class TransferModelConfig:
    """The networks of a transfer model folder (``model_type: transfer``)."""

    dit: DiTConfig = dataclasses.field(default_factory=DiTConfig)
    """The parent's DiT."""
    edm: EDMConfig = dataclasses.field(default_factory=EDMConfig)
    """The parent's EDM settings (the noise distribution may be changed for transfer training)."""
    text: TextConfig = dataclasses.field(default_factory=TextConfig)
    """The parent's caption encoder."""
    transfer: TransferConfig = dataclasses.field(default_factory=TransferConfig)
    """What transfer adds."""
