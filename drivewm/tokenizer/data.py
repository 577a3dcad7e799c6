"""Training and evaluation videos from clip shards: every camera of every clip is an independent video.

Clips stay H.264-compressed in memory and are decoded on use (a few recent videos are kept),
so a dataset of hours fits. Every random draw of a batch is a function of (seed, step), so a
resumed run sees exactly the batches an uninterrupted one would.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from pathlib import Path

import numpy as np
import torch
from einops import rearrange

from drivewm.clips import Clip, iter_clips
from drivewm.clips.video import decode_mp4
from drivewm.errors import DrivewmError


def is_holdout(key: str, holdout_percent: int) -> bool:
    """Deterministic split by clip key: the same clips are held out in training and evaluation."""
    return int(hashlib.sha1(key.encode()).hexdigest(), 16) % 100 < holdout_percent


def load_clips(clip_dir: str | Path, split: str = "all", holdout_percent: int = 0) -> list[Clip]:
    """Clips of a folder/tar: ``split`` is ``all``, ``train`` (not held out) or ``holdout``."""
    if split not in ("all", "train", "holdout") or not 0 <= holdout_percent < 100:
        # 150 % had held out every clip without a word ("train" then found none, after reading them all)
        raise DrivewmError(
            f"tokenizer data: split must be all, train or holdout and holdout_percent in [0, 100), "
            f"got {split!r} and {holdout_percent}"
        )
    clips = list(iter_clips(clip_dir))
    if split == "train":
        clips = [c for c in clips if not is_holdout(c.key, holdout_percent)]
    elif split == "holdout":
        clips = [c for c in clips if is_holdout(c.key, holdout_percent)]
    if not clips:
        raise DrivewmError(f"{clip_dir}: no clips in split {split!r} (holdout_percent={holdout_percent})")
    return clips


def to_model_range(frames: np.ndarray) -> torch.Tensor:
    """uint8 (T, H, W, 3) -> float (3, T, H, W) in [-1, 1]."""
    return rearrange(torch.from_numpy(frames).float() / 127.5 - 1.0, "t h w c -> c t h w")


def to_uint8(video: torch.Tensor) -> np.ndarray:
    """float (3, T, H, W) in [-1, 1] -> uint8 (T, H, W, 3)."""
    return rearrange(((video.clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8), "c t h w -> t h w c").numpy()


class CameraVideos:
    """Every (clip, camera) video of a list of clips, decoded on use with a small LRU cache."""

    def __init__(self, clips: list[Clip], cache_size: int = 64):
        self.clips = clips
        self.items = [(i, cam) for i, clip in enumerate(clips) for cam in clip.meta.cameras]
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self.cache_size = cache_size

    def __len__(self) -> int:
        return len(self.items)

    def name(self, i: int) -> str:
        clip_index, cam = self.items[i]
        return f"{self.clips[clip_index].key}.{cam}"

    def frames(self, i: int) -> np.ndarray:
        """uint8 (T, H, W, 3) of video ``i``."""
        if i in self._cache:
            self._cache.move_to_end(i)
            return self._cache[i]
        clip_index, cam = self.items[i]
        clip = self.clips[clip_index]
        frames = decode_mp4(clip.mp4[cam], clip.meta.num_frames, f"clip {clip.key} {cam}")
        self._cache[i] = frames
        if len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return frames
