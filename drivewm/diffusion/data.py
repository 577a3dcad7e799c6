"""Training samples from the latent cache: one sample per (clip, camera view), normalised latents.

Latents are normalised per channel with the tokenizer's statistics recorded in the cache's
index, ``(z - mean) / std``, then scaled to ``sigma_data`` (0.5) standard deviation (Cosmos
trains EDM on latents with sigma_data 0.5).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import torch

from drivewm.clips.latents import LatentCache
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class LatentSample:
    """One view of one clip: ``latents`` (c, t, h, w) normalised, its caption and frame rate."""

    latents: torch.Tensor
    caption: str
    fps: float


def normalize_latents(z: torch.Tensor, mean: torch.Tensor, std: torch.Tensor, sigma_data: float) -> torch.Tensor:
    """Raw tokenizer latents (..., c, t, h, w) -> per-channel standardised, times ``sigma_data``."""
    shape = (-1, 1, 1, 1)
    return (z - mean.view(shape)) / std.view(shape) * sigma_data


def denormalize_latents(x: torch.Tensor, mean: torch.Tensor, std: torch.Tensor, sigma_data: float) -> torch.Tensor:
    """Inverse of :func:`normalize_latents`."""
    shape = (-1, 1, 1, 1)
    return x / sigma_data * std.view(shape).to(x) + mean.view(shape).to(x)


class LatentDataset:
    """Samples (clip, view) of a latent cache; all clips must share one latent shape."""

    def __init__(self, cache_dir: str | Path, sigma_data: float = 0.5, frames: int | None = None):
        self.cache = LatentCache(cache_dir)
        self.sigma_data = sigma_data
        first = self.cache[0]
        self.num_views = first.latents.shape[0]
        self.clip_shape = tuple(first.latents.shape[1:])  # (c, t, h, w) of the cached clips
        if frames is not None and not 1 <= frames <= self.clip_shape[1]:
            raise DrivewmError(
                f"{self.cache.dir}: cannot take {frames} latent frames of clips with {self.clip_shape[1]}"
            )
        self.frames = frames or self.clip_shape[1]  # latent frames per sample, from the first
        self.latent_shape = (*self.clip_shape[:1], self.frames, *self.clip_shape[2:])  # (c, t, h, w) of a sample
        self.fps = float(first.meta.fps)

    def __len__(self) -> int:
        return len(self.cache) * self.num_views

    @functools.lru_cache(maxsize=256)  # noqa: B019 (bounded; a dataset lives as long as its training run)
    def _clip(self, i: int):
        clip = self.cache[i]
        if tuple(clip.latents.shape[1:]) != self.clip_shape or clip.latents.shape[0] != self.num_views:
            raise DrivewmError(
                f"{self.cache.dir}: clip {clip.meta.key} latents {tuple(clip.latents.shape)} differ from the first "
                f"clip's ({self.num_views}, {', '.join(map(str, self.clip_shape))}); re-encode at one resolution"
            )
        return clip

    def __getitem__(self, i: int) -> LatentSample:
        clip = self._clip(i // self.num_views)
        view = i % self.num_views
        camera = clip.meta.cameras[view] if view < len(clip.meta.cameras) else ""
        caption = clip.meta.view_captions.get(camera) or clip.meta.caption
        z = clip.latents[view, :, : self.frames]  # (c, t, h, w)
        z = normalize_latents(z, self.cache.latent_mean, self.cache.latent_std, self.sigma_data)
        return LatentSample(z, caption, float(clip.meta.fps))

    def captions(self) -> list[str]:
        """The distinct captions, in order of first appearance."""
        return list(dict.fromkeys(self[i].caption for i in range(len(self))))
