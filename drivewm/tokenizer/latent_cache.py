"""``drivewm tokenizer encode``: tokenizer latents of every clip, written next to the clips as the
latent cache of drivewm/clips/latents.py (``CLIPDIR/latents/NAME/``) that the diffusion stages
read instead of video. Encoding again keeps every latent file that the same clip, tokenizer and
tiling made (their fingerprint is in the file), so an interrupted encode resumes and a clip folder
that grew encodes only its new clips."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from drivewm.atomic import remove_dead_temporaries
from drivewm.clips import Clip
from drivewm.clips.latents import (
    LATENT_CACHE_VERSION,
    cached_latent_row,
    latent_cache_dir,
    write_latent_clip,
    write_latent_index,
)
from drivewm.clips.shards import BadClip, read_clips
from drivewm.config import to_dict
from drivewm.errors import BatchError, DrivewmError
from drivewm.layout.render import render_layout
from drivewm.model_folders import portable_reference
from drivewm.paths import check_confined
from drivewm.tokenizer.data import to_model_range
from drivewm.tokenizer.model import Tokenizer
from drivewm.tokenizer.tiling import TilingConfig, encode_tiled


def clip_video(clip: Clip) -> torch.Tensor:
    """All cameras of a clip as (V, 3, T, H, W) in [-1, 1] (rig order; V is the batch)."""
    return torch.stack([to_model_range(clip.video(cam)) for cam in clip.meta.cameras])


def clip_layout_video(clip: Clip) -> torch.Tensor | None:
    """The clip's layout drawn into its own cameras (drivewm.layout.render) as (V, 3, T, H, W) in
    [-1, 1], or None for a clip whose log had no layout."""
    layout = clip.layout()
    if layout is None:
        return None
    frames = render_layout(clip.meta.get_rig().subset(clip.meta.cameras), layout)  # (V, T, H, W, 3) uint8
    return torch.stack([to_model_range(v) for v in frames])


def encode_clips(
    model_dir: str | Path,
    clip_dir: str | Path,
    name: str | None = None,
    tiling: TilingConfig | None = None,
    progress: bool = True,
) -> dict:
    """Encode every clip of ``clip_dir`` with the tokenizer in ``model_dir``.

    A clip the tokenizer cannot take (frames not 1 + k*f, size not a multiple of the spatial
    compression, an unreadable clip or shard, a key seen before) is skipped and reported; the rest
    are kept. No clip encoded raises :class:`BatchError` with one line per skipped clip. A latent file
    already written from the same clip (meta, pixels, poses), tokenizer files and tiling is kept
    as it is. Returns {"cache": path, "encoded": n clips in the index, "reused": how many of them
    were kept, "skipped": [{"key", "reason"}]}.
    """
    tok = Tokenizer.from_pretrained(model_dir)
    cache_dir = latent_cache_dir(clip_dir, name, model_dir)
    check_confined(cache_dir)  # made here, before any atomic write checks it
    cache_dir.mkdir(parents=True, exist_ok=True)
    remove_dead_temporaries(cache_dir)  # a killed encode's unfinished latent files
    tiling = tiling or TilingConfig(chunk_latent_frames=None, tile_latent=None)
    maker = _maker_fingerprint(Path(model_dir), tiling)
    rows, skipped, reused = [], [], 0
    for clip in tqdm(read_clips(clip_dir), desc="tokenizer encode", disable=not progress):
        try:
            row = _encode_one(tok, clip, tiling, cache_dir, {r["key"] for r in rows}, maker)
        except DrivewmError as exc:
            skipped.append({"key": clip.name if isinstance(clip, BadClip) else clip.key, "reason": str(exc)})
            continue
        reused += row.pop("reused")
        rows.append(row)
    if not rows:
        lines = [s["reason"] for s in skipped]
        raise BatchError(f"{clip_dir}: no clip could be encoded ({len(skipped)} failed)", lines or ["no clips found"])
    info = {
        "path": str(Path(model_dir).resolve()),
        # read first: survives the clips and the tokenizer moving together, or drivewm installed elsewhere
        "reference": portable_reference(model_dir, cache_dir, Path(clip_dir).resolve().parent.parent),
        "config": to_dict(tok.config),
        "latent_mean": tok.latent_mean.tolist(),
        "latent_std": tok.latent_std.tolist(),
    }
    write_latent_index(cache_dir, info, rows)
    return {"cache": str(cache_dir), "encoded": len(rows), "reused": reused, "skipped": skipped}


def _maker_fingerprint(model_dir: Path, tiling: TilingConfig) -> str:
    """sha256 of the cache format, the tiling and the tokenizer folder's config and weights: what,
    beside the clip, decides the latent file."""
    digest = hashlib.sha256(json.dumps([LATENT_CACHE_VERSION, to_dict(tiling)], sort_keys=True).encode())
    for path in sorted([model_dir / "config.json", *model_dir.glob("*.safetensors")]):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _encode_one(
    tok: Tokenizer, clip: Clip | BadClip, tiling: TilingConfig, cache_dir: Path, done: set[str], maker: str
) -> dict:
    """Encode and write one clip, or keep its latent file if the same clip, tokenizer and tiling
    wrote it; its index row with "reused". Raises DrivewmError for a clip to skip."""
    if isinstance(clip, BadClip):
        raise DrivewmError(clip.reason)
    if clip.key in done:  # two shards with one key would overwrite one latent file with another clip
        raise DrivewmError(f"clip {clip.key}: key seen before in {clip.meta.source_log!r}'s dataset; kept the first")
    video = clip_video(clip)  # decoding the clip is what an unreadable one fails on, kept or not
    digest = hashlib.sha256(maker.encode())
    digest.update(json.dumps(clip.meta.to_json(), sort_keys=True).encode())
    digest.update(video.numpy().tobytes())
    if clip.has_layout:  # the layout video is drawn from it: a clip without layout keeps its old fingerprint
        digest.update(clip.layout_npz)
    digest.update(np.ascontiguousarray(clip.T_world_from_ego, dtype=np.float64).tobytes())
    source = digest.hexdigest()
    row = cached_latent_row(cache_dir, clip.meta, source)
    if row is not None:
        return {**row, "reused": 1}
    latents = encode_tiled(tok, video, tiling)  # (V, c, t, h, w)
    layout_video = clip_layout_video(clip)
    layout = None if layout_video is None else encode_tiled(tok, layout_video, tiling)
    row = write_latent_clip(cache_dir, clip.meta, latents, clip.T_world_from_ego, source, layout)
    return {**row, "reused": 0}
