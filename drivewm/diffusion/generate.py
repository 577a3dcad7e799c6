"""Latents to pixels and pictures: decoding through the tokenizer (or a latent preview without one),
contact sheets, and the metadata of a generated clip. Shared by training previews and drivewm.generate.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch
from einops import rearrange
from PIL import Image, ImageDraw

from drivewm.atomic import atomic_path
from drivewm.clips.format import ClipMeta
from drivewm.tokenizer import Tokenizer


def latents_preview(latents: torch.Tensor, upscale: int = 8) -> np.ndarray:
    """Without a tokenizer: the first three latent channels as RGB ([-1, 1] -> uint8), nearest-upscaled.

    (B, c, t, h, w) -> uint8 (B, t, h*upscale, w*upscale, 3)."""
    rgb = latents[:, :3] if latents.shape[1] >= 3 else latents[:, :1].expand(-1, 3, -1, -1, -1)
    rgb = rgb.repeat_interleave(upscale, dim=3).repeat_interleave(upscale, dim=4)
    return video_to_uint8(rgb)


def video_to_uint8(video: torch.Tensor) -> np.ndarray:
    """(B, 3, T, H, W) in [-1, 1] -> uint8 RGB (B, T, H, W, 3)."""
    frames = ((video.float().clamp(-1, 1) + 1) * 127.5).round().to(torch.uint8)
    return rearrange(frames, "b c t h w -> b t h w c").cpu().numpy()


def warn_if_preview(model_dir: str | Path, tokenizer_dir: str | None) -> None:
    """Say on stderr that a model folder without a tokenizer generates latent previews, not images."""
    if not tokenizer_dir:
        print(
            f"warning: {model_dir} records no tokenizer: its samples are latent previews (the first three latent "
            "channels as colours), not images; retrain it with --tokenizer TOKDIR",
            file=sys.stderr,
        )


@torch.no_grad()
def decode_latents(latents: torch.Tensor, tokenizer_dir: str | None, device: torch.device | str = "cpu") -> np.ndarray:
    """Raw latents (B, c, t, h, w) -> uint8 video (B, T, H, W, 3) with the tokenizer on ``device``
    (a preview of the latents themselves if None)."""
    if tokenizer_dir is None:
        return latents_preview(latents)

    tokenizer = Tokenizer.from_pretrained(tokenizer_dir).to(device)
    return np.concatenate([video_to_uint8(tokenizer.decode(z[None].to(device))) for z in latents])


def write_grid_png(
    videos: np.ndarray, path: str | Path, captions: list[str] | None = None, max_frames: int = 6
) -> Path:
    """Contact sheet: one row per video (B, T, H, W, 3) uint8, ``max_frames`` frames spread over time."""
    b, t = videos.shape[:2]
    cols = np.linspace(0, t - 1, min(t, max_frames)).round().astype(int)
    sheet = rearrange(videos[:, cols], "b n h w c -> (b h) (n w) c")
    image = Image.fromarray(np.ascontiguousarray(sheet))
    if captions:
        draw, row_h = ImageDraw.Draw(image), videos.shape[2]
        for i, caption in enumerate(captions[:b]):
            draw.text((4, i * row_h + 2), caption[:80], fill=(255, 255, 0))
    path = Path(path)
    with atomic_path(path) as tmp:
        image.save(tmp, format="PNG")
    return path


def clip_meta(key: str, rig: dict, fps: float, num_frames: int, prompt: str, extra: dict) -> ClipMeta:
    """Metadata of one generated clip (source_log ``generated``, timestamps from fps)."""
    step_ns = int(round(1e9 / fps))
    return ClipMeta(
        key=key,
        source_log="generated",
        start_time_ns=0,
        fps=fps,
        timestamps_ns=[i * step_ns for i in range(num_frames)],
        rig=rig,
        caption=prompt,
        extra=extra,
    )
