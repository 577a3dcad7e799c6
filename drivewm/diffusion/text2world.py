"""The Text2World model: DiT + EDM denoiser + text encoder + what it needs to turn samples into video.

Model folder (docs/DESIGN.md section 4): ``config.json`` with ``model_type: "text2world"``, the
:class:`Text2WorldConfig` and the :class:`LatentInfo` (latent shape and statistics, frame rate,
camera, tokenizer folder), and ``model.safetensors`` with the DiT's (EMA) weights.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import torch

from drivewm.config import frame_rate, from_dict, require, to_dict
from drivewm.device import resolve_device
from drivewm.diffusion.data import denormalize_latents, normalize_latents
from drivewm.diffusion.denoiser import Conditioning, EDMConfig, EDMDenoiser
from drivewm.diffusion.dit import DiT
from drivewm.diffusion.dit_config import DiTConfig, upgrade_saved_config
from drivewm.diffusion.sampling import sample
from drivewm.errors import DrivewmError
from drivewm.model_folders import SHIPPED_PREFIX, resolve_model_folder, resolve_reference
from drivewm.text import TextConfig, build_text_encoder
from drivewm.train.checkpoint import load_model_folder, load_weights, read_model_config, save_model_folder

MODEL_TYPE = "text2world"
#: The most latent values one sample may have (c * t * h * w): 256 MB of float32, ~18x a 33-frame 1280x720
#: clip coded 8x8x4 with 16 channels. Sampling holds several tensors of this size per view, so a typo's
#: ``latent_shape`` (77 GB) is refused where the config is read, not met as an allocation failure.
MAX_LATENT_VALUES = 2**26


@dataclasses.dataclass
class Text2WorldConfig:
    """The networks: backbone, EDM settings and text encoder."""

    dit: DiTConfig = dataclasses.field(default_factory=DiTConfig)
    """The DiT backbone."""
    edm: EDMConfig = dataclasses.field(default_factory=EDMConfig)
    """Preconditioning, noise distribution, CFG dropout, Video2World frames."""
    text: TextConfig = dataclasses.field(default_factory=TextConfig)
    """Caption encoder (frozen)."""


@dataclasses.dataclass
class LatentInfo:
    """What the model was trained on, to sample and decode without the data."""

    latent_shape: list[int]
    """(c, t, h, w) of one sample's latents."""
    latent_mean: list[float]
    """Per-channel mean of the tokenizer's latents (c,)."""
    latent_std: list[float]
    """Per-channel std of the tokenizer's latents (c,)."""
    fps: float = 10.0
    """Video frame rate of the training clips."""
    tokenizer: str | None = None
    """Tokenizer model folder that decodes the latents (absolute path)."""
    rig: dict = dataclasses.field(default_factory=dict)
    """Single-camera rig (dict form) written into generated clips."""

    def validate(self) -> None:
        shape = self.latent_shape
        require(len(shape) == 4 and min(shape) >= 1, "latent_shape", shape, "4 sizes (c, t, h, w) >= 1")
        require(math.prod(shape) <= MAX_LATENT_VALUES, "latent_shape", shape, f"<= {MAX_LATENT_VALUES:,} values")
        for name in ("latent_mean", "latent_std"):  # one per channel: a shorter list broadcasts silently
            require(len(getattr(self, name)) == shape[0], name, getattr(self, name), f"{shape[0]} numbers (c)")
        require(min(self.latent_std) > 0, "latent_std", self.latent_std, "> 0 (a 0 turns every sample flat)")
        frame_rate(self, "fps")


def read_latent_info(info: dict, folder: str | Path, dit: DiTConfig) -> LatentInfo:
    """The ``latent`` entry of a model folder's config.json, checked to fit the folder's ``dit``; a relative
    tokenizer path (shipped weights point at ``../tokenizer``) is resolved against the model folder
    (``shipped:KIND`` names the installed folder, drivewm.model_folders)."""
    folder = resolve_model_folder(folder)
    where = f"{Path(folder) / 'config.json'} latent"
    latent = from_dict(LatentInfo, info.get("latent", {}), where)
    c, t, h, w = latent.latent_shape
    if c != dit.in_channels or t % dit.patch_t or h % dit.patch_size or w % dit.patch_size:
        raise DrivewmError(
            f"{where}: latent_shape {latent.latent_shape} does not fit the network (in_channels {dit.in_channels}, "
            f"t a multiple of patch_t {dit.patch_t}, h and w multiples of patch_size {dit.patch_size})"
        )
    if latent.tokenizer:
        tokenizer = resolve_reference(latent.tokenizer, folder)
        if latent.tokenizer.startswith(SHIPPED_PREFIX):
            check_shipped_statistics(latent, tokenizer, where)
        latent = dataclasses.replace(latent, tokenizer=str(tokenizer))
    return latent


def check_shipped_statistics(latent: LatentInfo, tokenizer: Path, where: str) -> None:
    """A model fine-tuned from the shipped weights records the shipped tokenizer by name, so a newer
    drivewm's tokenizer decodes it; refused (DrivewmError) when that tokenizer codes other latents
    than the model learned (its latent statistics differ): a decoder improved alone is taken, a new
    latent space is not."""
    info = read_model_config(tokenizer)
    for name in ("latent_mean", "latent_std"):
        if info.get(name) is None or not same_statistics(getattr(latent, name), info[name]):
            raise DrivewmError(
                f"{where}: the model learned the latents of another shipped tokenizer than {tokenizer} ({name} "
                "differs: a drivewm whose tokenizer codes other latents); set latent.tokenizer in its config.json "
                "to the tokenizer folder it was trained with"
            )


def same_statistics(a: list[float] | None, b: list[float] | None) -> bool:
    """Per-channel latent statistics equal up to half precision (either unknown counts as equal):
    shipped tokenizers store their statistics' buffers in fp16 (an 11-bit significand, so rounding
    moves a value by up to 2^-11 = 4.9e-4 of it) while their config.json keeps the fp32 values, and a
    cache or a model records the statistics the loaded tokenizer encoded with."""
    return a is None or b is None or (len(a) == len(b) and np.allclose(a, b, rtol=1e-3, atol=1e-6))


class Text2World:
    """Inference bundle. ``sample_latents(prompts, seeds) -> raw tokenizer latents (B, c, t, h, w)``."""

    def __init__(self, cfg: Text2WorldConfig, latent: LatentInfo):
        self.cfg = cfg
        self.latent = latent
        self.text_encoder = build_text_encoder(cfg.text)
        self.dit = DiT(cfg.dit).eval()
        self.denoiser = EDMDenoiser(self.dit, cfg.edm, cfg.dit.cond_mask_channel)
        self.device = torch.device("cpu")

    def to(self, device: str | torch.device) -> Text2World:
        """Run sampling on ``device`` (``auto``: CUDA when available); noise stays seeded on the CPU."""
        self.device = resolve_device(device)
        self.dit.to(self.device)
        return self

    def save_pretrained(self, path: str | Path, dit_state: dict[str, torch.Tensor] | None = None) -> None:
        """Write the model folder (``dit_state`` defaults to the DiT's current weights)."""
        state = dit_state if dit_state is not None else self.dit.state_dict()
        save_model_folder(path, MODEL_TYPE, to_dict(self.cfg), state, {"latent": to_dict(self.latent)})

    @classmethod
    def from_pretrained(cls, path: str | Path) -> Text2World:
        info, state = load_model_folder(path, MODEL_TYPE)
        where = f"{Path(path) / 'config.json'}"
        config = from_dict(Text2WorldConfig, upgrade_saved_config(info["config"]), where)
        model = cls(config, read_latent_info(info, path, config.dit))
        load_weights(model.dit, state, path)
        return model

    def conditioning(self, prompts: list[str], fps: float | None = None) -> Conditioning:
        """Caption embeddings and frame rate for ``prompts``, on the model's device."""
        emb, mask = self.text_encoder.encode(prompts)
        return Conditioning(
            emb.to(self.device),
            mask.to(self.device),
            torch.full((len(prompts),), fps or self.latent.fps, device=self.device),
        )

    @torch.no_grad()
    def sample_latents(
        self,
        prompts: list[str],
        seeds: list[int],
        steps: int = 35,
        guidance: float = 7.0,
        sampler: str = "heun",
        fps: float | None = None,
        cond_latents: torch.Tensor | None = None,
        guidance_interval: tuple[float, float] | None = None,
    ) -> torch.Tensor:
        """Generate raw (denormalised) latents (B, c, t, h, w), one per prompt, sample i from ``seeds[i]``.

        ``cond_latents`` (B, c, t, h, w) raw latents whose first ``edm.cond_frames`` frames are kept
        (Video2World models only). ``guidance_interval`` (lo, hi): guide only at sigma in (lo, hi].
        """
        c, t, h, w = self.latent.latent_shape
        cond = self.conditioning(prompts, fps)
        if cond_latents is not None:
            given = normalize_latents(cond_latents.cpu(), *self._stats(), self.cfg.edm.sigma_data)
            cond = dataclasses.replace(cond, cond_latents=given, cond_frames=self.cfg.edm.cond_frames)
        x = sample(
            self.denoiser,
            cond,
            (c, t, h, w),
            seeds,
            steps,
            guidance,
            sampler,
            device=self.device,
            guidance_interval=guidance_interval,
        )
        return denormalize_latents(x, *self._stats(), self.cfg.edm.sigma_data)

    def _stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.tensor(self.latent.latent_mean), torch.tensor(self.latent.latent_std)
