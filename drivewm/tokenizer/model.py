"""The tokenizer: a causal video autoencoder with continuous or FSQ latents (docs/DESIGN.md section 5).

``encode``: video (B, 3, T, H, W) in [-1, 1], T = 1 + k*f -> latents (B, c, 1 + k, H/s, W/s).
``decode`` inverts it. Frame 0 is coded alone and no latent frame depends on later frames, so a
single image (T = 1) is a valid input and long videos can be coded in chunks (see ``tiling.py``).
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from drivewm.config import from_dict, to_dict
from drivewm.errors import DrivewmError
from drivewm.tokenizer.causal import CausalContext, is_first
from drivewm.tokenizer.config import TokenizerConfig
from drivewm.tokenizer.fsq import FSQ
from drivewm.tokenizer.linear_code import LinearCode
from drivewm.tokenizer.networks import Decoder, Encoder
from drivewm.tokenizer.wavelet import patchify, unpatchify
from drivewm.train.checkpoint import load_model_folder, load_weights, save_model_folder

MODEL_TYPE = "drivewm-tokenizer"


class Tokenizer(nn.Module):
    """Causal video autoencoder. ``latent_mean`` / ``latent_std`` (c,) are per-channel latent
    statistics measured after training, for the diffusion stage's normalization."""

    def __init__(self, config: TokenizerConfig):
        super().__init__()
        config.validate()
        self.config = config
        self.encoder = Encoder(config)
        self.decoder = Decoder(config)
        self.quantizer = FSQ(config.fsq_levels) if config.quantizer == "fsq" else None
        self.linear = LinearCode(config) if config.linear_code == "pca" else None
        if self.linear is not None:  # the networks start silent: the untrained tokenizer is the linear code
            self.encoder.head.silence()
            self.decoder.head.silence()
        self.register_buffer("latent_mean", torch.zeros(config.code_channels))
        self.register_buffer("latent_std", torch.ones(config.code_channels))

    def encode(self, video: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        """(B, 3, T, H, W) in [-1, 1] -> latents (B, c, t, H/s, W/s); FSQ latents are the codes in [-1, 1].

        With a :class:`CausalContext` the call codes one chunk of a longer video: the first chunk
        has T = 1 + k*f frames, later chunks k*f frames (they give k latent frames).
        """
        self.check_video(video, is_first(ctx))
        x = self.patch(video, is_first(ctx))  # (B, patch_channels, T', H/p, W/p)
        z = self.encoder(x, ctx)  # (B, c, t, h, w)
        if self.linear is not None:
            z = z + self.linear.encode(x, is_first(ctx))
        return self.quantizer(z) if self.quantizer is not None else z

    def patch(self, video: torch.Tensor, first_chunk: bool = True) -> torch.Tensor:
        """The Haar patch (B, patch_channels, T', H/p, W/p) the networks (and the linear code) see."""
        return patchify(video, self.config.patch_size, self.config.patch_time, first_chunk)

    def decode(self, latents: torch.Tensor, ctx: CausalContext | None = None) -> torch.Tensor:
        """Latents (B, c, t, h, w) -> video (B, 3, T, h*s, w*s), T = 1 + (t-1)*f (t*f for a later chunk)."""
        self.check_latents(latents)
        x = self.decoder(latents, ctx)  # (B, patch_channels, T', H/p, W/p)
        if self.linear is not None:
            x = x + self.linear.decode(latents, is_first(ctx))
        return unpatchify(x, self.config.patch_size, self.config.patch_time, is_first(ctx))  # (B, 3, T, H, W)

    def forward(self, video: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(reconstruction, latents) of ``video`` (B, 3, T, H, W)."""
        latents = self.encode(video)
        return self.decode(latents), latents

    def indices(self, latents: torch.Tensor) -> torch.Tensor:
        """FSQ code indices (B, t, h, w) of FSQ latents; continuous tokenizers have none."""
        if self.quantizer is None:
            raise DrivewmError("this tokenizer is continuous; code indices exist only for FSQ tokenizers")
        return self.quantizer.codes_to_indices(latents)

    # -- validation -------------------------------------------------------------------------------

    def check_video(self, video: torch.Tensor, first_chunk: bool = True) -> None:
        """Raise DrivewmError unless ``video`` is (B, 3, T, H, W) with T and H, W the model accepts."""
        f, s = self.config.temporal_compression, self.config.spatial_compression
        if video.ndim != 5:
            raise DrivewmError(f"video must be (B, 3, T, H, W), got shape {tuple(video.shape)}")
        _, channels, frames, height, width = video.shape
        if channels != 3:
            raise DrivewmError(f"video has {channels} channels (shape {tuple(video.shape)}), expected 3 (RGB) at dim 1")
        if first_chunk and (frames - 1) % f:
            raise DrivewmError(
                f"video has {frames} frames; this tokenizer takes T = 1 + k*{f} (e.g. 1, {1 + f}, {1 + 2 * f})"
            )
        if not first_chunk and (frames == 0 or frames % f):
            raise DrivewmError(f"a continuation chunk has {frames} frames; it needs a positive multiple of {f}")
        if height % s or width % s:
            raise DrivewmError(
                f"video is {height}x{width} (HxW); height and width must be multiples of {s} "
                f"(e.g. {width // s * s}x{height // s * s} WxH: curate clips at such a size with "
                f"--set 'resolution=[{width // s * s},{height // s * s}]')"
            )

    def check_latents(self, latents: torch.Tensor) -> None:
        c = self.config.code_channels
        if latents.ndim != 5 or latents.shape[1] != c:
            raise DrivewmError(
                f"latents must be (B, {c}, t, h, w) for this tokenizer, got shape {tuple(latents.shape)}"
            )

    # -- model folders ----------------------------------------------------------------------------

    def save_pretrained(self, path: str | Path, extra: dict | None = None) -> None:
        """Write ``config.json`` + ``model.safetensors`` (docs/DESIGN.md section 4)."""
        stats = {"latent_mean": self.latent_mean.tolist(), "latent_std": self.latent_std.tolist()}
        save_model_folder(path, MODEL_TYPE, to_dict(self.config), self.state_dict(), {**stats, **(extra or {})})

    @classmethod
    def from_pretrained(cls, path: str | Path) -> Tokenizer:
        """Load a model folder (safetensors only: nothing is unpickled). Weights that do not
        match ``config.json`` raise DrivewmError naming the folder."""
        info, state = load_model_folder(path, MODEL_TYPE)
        config = from_dict(TokenizerConfig, info["config"], f"{Path(path) / 'config.json'} config")
        model = cls(config)
        load_weights(model, state, path)
        return model.eval()
