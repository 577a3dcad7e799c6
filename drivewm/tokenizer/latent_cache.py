"""``drivewm tokenizer encode``: tokenizer latents of every clip, written next to the clips as the
latent cache of drivewm/clips/latents.py (``CLIPDIR/latents/NAME/``) that the diffusion stages
read instead of video."""

from __future__ import annotations

from pathlib import Path

import torch
from tqdm import tqdm

from drivewm.clips import Clip, iter_clips
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.tokenizer.data import to_model_range
from drivewm.tokenizer.model import Tokenizer
from drivewm.tokenizer.tiling import TilingConfig, encode_tiled


def clip_video(clip: Clip) -> torch.Tensor:
    """All cameras of a clip as (V, 3, T, H, W) in [-1, 1] (rig order; V is the batch)."""
    return torch.stack([to_model_range(clip.video(cam)) for cam in clip.meta.cameras])


def encode_clips(
    model_dir: str | Path,
    clip_dir: str | Path,
    name: str | None = None,
    tiling: TilingConfig | None = None,
    progress: bool = True,
) -> dict:
    """Encode every clip of ``clip_dir`` with the tokenizer in ``model_dir``.

    A clip the tokenizer cannot take (frames not 1 + k*f, size not a multiple of the spatial
    compression, an unreadable video) is skipped and reported; the rest are kept.
    Returns {"cache": path, "encoded": n, "skipped": [{"key", "reason"}]}.
    """
    tok = Tokenizer.from_pretrained(model_dir)
    cache_dir = Path(clip_dir) / "latents" / (name or Path(model_dir).resolve().name)
    cache_dir.mkdir(parents=True, exist_ok=True)
    tiling = tiling or TilingConfig(chunk_latent_frames=None, tile_latent=None)
    rows, skipped = [], []
    for clip in tqdm(iter_clips(clip_dir), desc="tokenizer encode", disable=not progress):
        try:
            latents = encode_tiled(tok, clip_video(clip), tiling)  # (V, c, t, h, w)
        except DrivewmError as exc:
            skipped.append({"key": clip.key, "reason": str(exc)})
            continue
        rows.append(write_latent_clip(cache_dir, clip.meta, latents, clip.T_world_from_ego))
    if not rows:
        raise DrivewmError(f"{clip_dir}: no clip could be encoded ({skipped[0]['reason'] if skipped else 'no clips'})")
    info = {
        "path": str(Path(model_dir).resolve()),
        "config": to_dict(tok.config),
        "latent_mean": tok.latent_mean.tolist(),
        "latent_std": tok.latent_std.tolist(),
    }
    write_latent_index(cache_dir, info, rows)
    return {"cache": str(cache_dir), "encoded": len(rows), "skipped": skipped}
