"""``drivewm tokenizer decode``: latents from a latent cache, or clips (encoded then decoded),
back to one mp4 per clip and camera (``OUT/KEY.CAMERA.mp4``)."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import torch
from tqdm import tqdm

from drivewm.atomic import write_bytes
from drivewm.clips import Clip
from drivewm.clips.latents import LatentCache
from drivewm.clips.shards import BadClip, read_clips
from drivewm.clips.video import encode_mp4
from drivewm.errors import BatchError, DrivewmError
from drivewm.paths import child_path
from drivewm.tokenizer.data import to_uint8
from drivewm.tokenizer.evaluate import reconstruct
from drivewm.tokenizer.latent_cache import clip_video
from drivewm.tokenizer.model import Tokenizer
from drivewm.tokenizer.tiling import TilingConfig, decode_tiled


def _write_views(out_dir: Path, key: str, cameras: list[str], video: torch.Tensor, fps: float) -> list[Path]:
    """Write (V, 3, T, H, W) in [-1, 1] as one mp4 per camera."""
    paths = []
    for cam, view in zip(cameras, video):
        path = child_path(out_dir, key, cam, ext="mp4")
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
    """Decode a latent cache folder (has ``index.json``) or reconstruct a clip folder/tar into mp4s.

    A clip that cannot be read or decoded is skipped (one ``skipped:`` line on stderr); when nothing
    could be written, :class:`BatchError` lists every failure.
    """
    tok = Tokenizer.from_pretrained(model_dir)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tiling = tiling or TilingConfig(chunk_latent_frames=None, tile_latent=None)
    written: list[Path] = []
    failed: list[str] = []
    for key, decode in tqdm(_decoders(tok, source, tiling), desc="tokenizer decode", disable=not progress):
        if keys is not None and key not in keys:
            continue
        try:
            cameras, fps, video = decode()
        except DrivewmError as exc:
            failed.append(str(exc))
            continue
        written += _write_views(out_dir, key, cameras, video, fps)
    if not written:
        wanted = f"no clip with key {keys}" if keys else "no clips"
        raise BatchError(f"{source}: no clip could be decoded ({len(failed)} failed)", failed or [wanted])
    for reason in failed:
        print(f"skipped: {reason}", file=sys.stderr)
    return written


def _decoders(tok: Tokenizer, source: str | Path, tiling: TilingConfig) -> Iterator[tuple[str, Callable]]:
    """(clip key, () -> (cameras, fps, video (V, 3, T, H, W) in [-1, 1])) per clip of a latent cache
    or a clip folder; the callable raises DrivewmError for a clip that cannot be decoded."""
    if (Path(source) / "index.json").is_file():
        cache = LatentCache(source)
        for i, row in enumerate(cache.rows):
            yield row["key"], functools.partial(_decode_cached, tok, cache, i, tiling)
        return
    for clip in read_clips(source):
        name = clip.name if isinstance(clip, BadClip) else clip.key
        yield name, functools.partial(_reconstruct, tok, clip, tiling)


def _decode_cached(tok: Tokenizer, cache: LatentCache, i: int, tiling: TilingConfig):
    item = cache[i]
    return item.meta.cameras, item.meta.fps, decode_tiled(tok, item.latents, tiling).clamp(-1, 1)


def _reconstruct(tok: Tokenizer, clip: Clip | BadClip, tiling: TilingConfig):
    if isinstance(clip, BadClip):
        raise DrivewmError(clip.reason)
    recon, _ = reconstruct(tok, clip_video(clip), tiling)
    return clip.meta.cameras, clip.meta.fps, recon
