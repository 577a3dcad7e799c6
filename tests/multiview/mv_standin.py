"""A fixed, lossy stand-in for the tokenizer, cheap enough for the test budget.

Encode: keep video frames 0, 4, 8, ... (causal: latent frame i sees only frame 4i) and average-pool
RGB in [-1, 1] over s x s pixels. Decode: repeat each latent frame (the first once, the others 4
times, as a 4x causal tokenizer lays frames out) and upsample nearest. Same interface as
drivewm.tokenizer.Tokenizer (encode/decode on (B, C, T, H, W), config.*_compression).
"""

from __future__ import annotations

import types
from pathlib import Path

import torch
import torch.nn.functional as F
from einops import rearrange

from drivewm.clips import iter_clips
from drivewm.clips.latents import write_latent_clip, write_latent_index


class PoolTokenizer:
    def __init__(self, spatial: int = 32, temporal: int = 4):
        self.config = types.SimpleNamespace(spatial_compression=spatial, temporal_compression=temporal)

    def encode(self, video: torch.Tensor) -> torch.Tensor:
        """(B, 3, T, H, W) in [-1, 1] -> (B, 3, 1 + (T-1)/4, H/s, W/s)."""
        b = video.shape[0]
        frames = rearrange(video[:, :, :: self.config.temporal_compression], "b c t h w -> (b t) c h w")
        return rearrange(F.avg_pool2d(frames, self.config.spatial_compression), "(b t) c h w -> b c t h w", b=b)

    def decode(self, latents: torch.Tensor) -> torch.Tensor:
        tc, s = self.config.temporal_compression, self.config.spatial_compression
        frames = torch.cat([latents[:, :, :1], latents[:, :, 1:].repeat_interleave(tc, dim=2)], dim=2)
        return frames.repeat_interleave(s, dim=3).repeat_interleave(s, dim=4)


def write_pooled_cache(
    clip_dir: Path | list[Path], out: Path, tokenizer: PoolTokenizer, cameras: list[str] | None = None
) -> Path:
    """A real latent cache (drivewm.clips.latents) of every clip in ``clip_dir`` (one folder or several)
    coded by ``tokenizer``."""
    rows = []
    clips = (clip for d in (clip_dir if isinstance(clip_dir, list) else [clip_dir]) for clip in iter_clips(d))
    for clip in clips:
        names = cameras or clip.meta.cameras
        video = torch.from_numpy(clip.videos()[[clip.meta.cameras.index(n) for n in names]]).float() / 127.5 - 1
        z = tokenizer.encode(rearrange(video, "v t h w c -> v c t h w"))
        rows.append(write_latent_clip(out, clip.meta, z, clip.T_world_from_ego))
    write_latent_index(out, {"path": None, "latent_mean": [0.0] * 3, "latent_std": [0.5] * 3}, rows)
    return out
