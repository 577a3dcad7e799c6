"""``drivewm tokenizer decode``: latents from a latent cache, or clips (encoded then decoded),
back to one mp4 per clip and camera (``OUT/KEY.CAMERA.mp4``)."""

from __future__ import annotations

from pathlib import Path

import torch
from tqdm import tqdm

from drivewm.atomic import write_bytes
from drivewm.clips import iter_clips
from drivewm.clips.latents import LatentCache
from drivewm.clips.video import encode_mp4
from drivewm.tokenizer.data import to_uint8
from drivewm.tokenizer.evaluate import reconstruct
from drivewm.tokenizer.latent_cache import clip_video
from drivewm.tokenizer.model import Tokenizer
from drivewm.tokenizer.tiling import TilingConfig, decode_tiled


def _write_views(out_dir: Path, key: str, cameras: list[str], video: torch.Tensor, fps: float) -> list[Path]:
    """Write (V, 3, T, H, W) in [-1, 1] as one mp4 per camera."""
    paths = []
    for cam, view in zip(cameras, video):
        path = out_dir / f"{key}.{cam}.mp4"
        write_bytes(path, encode_mp4(to_uint8(view), fps))
        paths.append(path)
    return paths


@torch.no_grad()
def decode_to_mp4(
    model_dir: str | Path,
    source: str | Path,
    out_dir: str | Path,
    keys: list[str] | None = None,
    tiling: TilingConfig | None = None,
    progress: bool = True,
) -> list[Path]:
    """Decode a latent cache folder (has ``index.json``) or reconstruct a clip folder/tar into mp4s."""
    tok = Tokenizer.from_pretrained(model_dir)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tiling = tiling or TilingConfig(chunk_latent_frames=None, tile_latent=None)
    written: list[Path] = []
    if (Path(source) / "index.json").is_file():
        cache = LatentCache(source)
        for i in tqdm(range(len(cache)), desc="tokenizer decode", disable=not progress):
            item = cache[i]
            if keys is None or item.meta.key in keys:
                video = decode_tiled(tok, item.latents, tiling).clamp(-1, 1)  # (V, 3, T, H, W)
                written += _write_views(out_dir, item.meta.key, item.meta.cameras, video, item.meta.fps)
        return written
    for clip in tqdm(iter_clips(source), desc="tokenizer reconstruct", disable=not progress):
        if keys is None or clip.key in keys:
            recon, _ = reconstruct(tok, clip_video(clip), tiling)
            written += _write_views(out_dir, clip.key, clip.meta.cameras, recon, clip.meta.fps)
    return written
