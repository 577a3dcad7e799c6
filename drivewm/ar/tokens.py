"""Token caches: FSQ code indices of curated clips, read from the latent cache that ``drivewm tokenizer
encode`` writes for an FSQ tokenizer (drivewm/clips/latents.py).

An FSQ tokenizer's latents are its codes, values k / (L_i // 2) - 1 on each channel's grid, stored
exactly in float32; :meth:`drivewm.tokenizer.fsq.FSQ.codes_to_indices` turns them into the integer
indices without loss, so the latent cache is the token cache and one encode serves both families. A
cache from a continuous tokenizer, or from another tokenizer than the one named, is refused.

One sample is one camera view of one clip: its tokens (t, h, w), caption, frame rate, the view's
Plucker rays, and the ego pose of each latent frame in the first latent frame's ego frame.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import torch

from drivewm.clips.latents import LatentCache
from drivewm.errors import DrivewmError
from drivewm.geometry import invert_T, yaw_of
from drivewm.tokenizer.data import is_holdout
from drivewm.tokenizer.fsq import FSQ
from drivewm.train.checkpoint import read_model_config
from drivewm.views.rays import plucker_rays

TOKENIZER_TYPE = "drivewm-tokenizer"


@dataclasses.dataclass
class TokenSample:
    """One view of one clip."""

    tokens: torch.Tensor
    """(t, h, w) long FSQ indices."""
    caption: str
    fps: float
    rays: torch.Tensor
    """(h*w, 6) Plucker rays of the view's token grid (ego frame, metres), row-major."""
    ego: torch.Tensor
    """(t, 3) float32 x, y (m) and yaw (rad) of each latent frame's ego in the first one's frame."""


def fsq_levels(tokenizer_config: dict, where: str) -> list[int]:
    """The FSQ levels of a saved tokenizer config; a continuous tokenizer raises DrivewmError."""
    if tokenizer_config.get("quantizer") != "fsq":
        raise DrivewmError(
            f"{where}: a continuous tokenizer (quantizer {tokenizer_config.get('quantizer')!r}); the autoregressive "
            "model needs FSQ tokens (train one with 'drivewm tokenizer train --fsq')"
        )
    return list(tokenizer_config["fsq_levels"])


def check_cache_tokenizer(cache: LatentCache, tokenizer_dir: Path) -> dict:
    """The config of the FSQ tokenizer ``tokenizer_dir``, refused unless it encoded ``cache`` (the same config
    and latent statistics, which every training run measures anew)."""
    info = read_model_config(tokenizer_dir, TOKENIZER_TYPE)
    fsq_levels(info["config"], str(tokenizer_dir))
    same = all(cache.tokenizer.get(k) == info.get(k) for k in ("latent_mean", "latent_std"))
    if cache.tokenizer.get("config") != info["config"] or not same:
        raise DrivewmError(
            f"{cache.dir}: tokens were encoded by another tokenizer ({cache.tokenizer.get('path')}) "
            f"than {tokenizer_dir}"
        )
    return info["config"]


def latent_frame_poses(T_world_from_ego: np.ndarray, temporal_compression: int, frames: int) -> torch.Tensor:
    """(frames, 3) x, y, yaw of latent frame k's ego (video frame k*f, the last frame it codes) in latent
    frame 0's ego frame."""
    T0_inv = invert_T(T_world_from_ego[0])
    rows = []
    for k in range(frames):
        T = T0_inv @ T_world_from_ego[min(k * temporal_compression, len(T_world_from_ego) - 1)]
        rows.append([T[0, 3], T[1, 3], yaw_of(T)])
    return torch.tensor(rows, dtype=torch.float32)


class TokenDataset:
    """Samples (clip, view) of an FSQ tokenizer's latent cache: ``len``, ``[i]`` -> :class:`TokenSample`.
    ``split`` (all, train, holdout) keeps the clips the key-hash split of drivewm.tokenizer.data puts there,
    the split the tokenizer was trained on."""

    def __init__(self, cache_dir: str | Path, frames: int | None = None, split: str = "all", holdout_percent: int = 0):
        self.cache = LatentCache(cache_dir)
        holdout = [is_holdout(row["key"], holdout_percent) for row in self.cache.rows]
        self.clips = [i for i, held in enumerate(holdout) if split == "all" or held == (split == "holdout")]
        if not self.clips:
            raise DrivewmError(f"{self.cache.dir}: no clips in split {split!r} (holdout_percent {holdout_percent})")
        config = self.cache.tokenizer.get("config", {})
        self.fsq = FSQ(fsq_levels(config, str(self.cache.dir)))
        self.temporal_compression = int(config["temporal_compression"])
        first = self.cache[self.clips[0]]
        self.num_views = first.latents.shape[0]
        self.clip_frames = first.latents.shape[2]
        if frames is not None and not 1 <= frames <= self.clip_frames:
            raise DrivewmError(f"{self.cache.dir}: cannot take {frames} latent frames of clips with {self.clip_frames}")
        self.frames = frames or self.clip_frames
        self.grid_hw = tuple(first.latents.shape[3:])
        self.fps = float(first.meta.fps)

    @property
    def vocab_size(self) -> int:
        return self.fsq.codebook_size

    def __len__(self) -> int:
        return len(self.clips) * self.num_views

    @functools.lru_cache(maxsize=512)  # noqa: B019 (bounded; a dataset lives as long as its run)
    def _clip(self, i: int) -> tuple[torch.Tensor, object, torch.Tensor, torch.Tensor]:
        clip = self.cache[self.clips[i]]
        latents = clip.latents[:, :, : self.frames]  # (V, c, t, h, w)
        if latents.shape[0] != self.num_views or tuple(latents.shape[2:]) != (self.frames, *self.grid_hw):
            raise DrivewmError(
                f"{self.cache.dir}: clip {clip.meta.key} latents {tuple(clip.latents.shape)} differ "
                "from the first clip's; re-encode at one resolution"
            )
        tokens = self.fsq.codes_to_indices(latents)  # (V, t, h, w)
        rays = plucker_rays(clip.meta.get_rig(), self.grid_hw)  # (V, h*w, 6)
        ego = latent_frame_poses(clip.T_world_from_ego, self.temporal_compression, self.frames)
        return tokens, clip.meta, rays, ego

    def __getitem__(self, i: int) -> TokenSample:
        tokens, meta, rays, ego = self._clip(i // self.num_views)
        view = i % self.num_views
        caption = meta.view_captions.get(meta.cameras[view]) or meta.caption
        return TokenSample(tokens[view], caption, float(meta.fps), rays[view], ego)

    def captions(self) -> list[str]:
        return list(dict.fromkeys(self[i].caption for i in range(len(self))))
