"""``drivewm tokenizer eval``: reconstruction quality on (held-out) clips.

``metrics.json``: top level ``psnr`` (dB), ``ssim``, ``temporal_l1`` (8-bit levels),
``flicker_ratio``, ``compression_ratio`` (input values per latent value) and, for FSQ,
``codebook_usage`` (fraction of codes used) and ``bits_per_pixel``; per clip under ``clips``.
``side_by_side.png``: per camera of the first clip, input | reconstruction | |error| x4 at the
first, middle and last frame.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from tqdm import tqdm

from drivewm.atomic import atomic_path, write_json
from drivewm.clips.shards import spread
from drivewm.errors import DrivewmError
from drivewm.tokenizer.data import load_clips, to_uint8
from drivewm.tokenizer.latent_cache import clip_video
from drivewm.tokenizer.metrics import psnr, ssim, temporal_metrics
from drivewm.tokenizer.model import Tokenizer
from drivewm.tokenizer.tiling import TilingConfig, decode_tiled, encode_tiled


def usable_frames(frames: int, f: int) -> int:
    """The longest 1 + k*f prefix of ``frames`` frames."""
    return 1 + (frames - 1) // f * f


@torch.no_grad()
def reconstruct(
    tok: Tokenizer, video: torch.Tensor, tiling: TilingConfig | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """(reconstruction, latents) of (B, 3, T, H, W) in [-1, 1], cut to the longest 1 + k*f frames."""
    video = video[:, :, : usable_frames(video.shape[2], tok.config.temporal_compression)]
    tiling = tiling or TilingConfig(chunk_latent_frames=None, tile_latent=None)
    latents = encode_tiled(tok, video, tiling)
    return decode_tiled(tok, latents, tiling).clamp(-1, 1), latents


def video_metrics(recon: torch.Tensor, video: torch.Tensor) -> dict[str, float]:
    """PSNR, SSIM and temporal stability of a reconstruction (B, 3, T, H, W) in [-1, 1]."""
    video = video[:, :, : recon.shape[2]]
    out = {"psnr": psnr(recon, video), "ssim": ssim(recon, video).item()}
    if video.shape[2] > 1:
        out.update(temporal_metrics(recon, video))
    return out


def evaluate_tokenizer(
    model_dir: str | Path,
    clip_dir: str | Path,
    out_dir: str | Path,
    split: str = "all",
    holdout_percent: int = 10,
    max_clips: int | None = None,
    max_views: int | None = None,
    progress: bool = True,
) -> dict:
    """Score the tokenizer in ``model_dir`` on the clips of ``clip_dir`` (``max_clips`` of them spread
    evenly over the sorted clips, as ``drivewm eval --max-clips`` takes them; the first ``max_views``
    cameras of each); writes metrics.json and side_by_side.png."""
    for name, limit in (("max_clips", max_clips), ("max_views", max_views)):
        if limit is not None and limit < 1:  # a slice [:-1] would quietly leave out the last one
            raise DrivewmError(f"tokenizer eval: {name} must be >= 1, got {limit}")
    tok = Tokenizer.from_pretrained(model_dir)
    clips = spread(load_clips(clip_dir, split, holdout_percent), max_clips)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    per_clip, codes, first, skipped = {}, [], None, {}
    for clip in tqdm(clips, desc="tokenizer eval", disable=not progress):
        try:
            video = clip_video(clip)[:max_views]  # (V, 3, T, H, W)
            recon, latents = reconstruct(tok, video)
        except DrivewmError as exc:  # a clip the tokenizer cannot take is reported, the rest scored
            skipped[clip.key] = str(exc)
            continue
        per_clip[clip.key] = video_metrics(recon, video)
        if tok.quantizer is not None:
            codes.append(tok.indices(latents).flatten())
        if first is None:
            first = (video[:, :, : recon.shape[2]], recon, latents)
    if not per_clip:
        raise DrivewmError(f"{clip_dir}: no clip could be scored ({next(iter(skipped.values()))})")
    metrics = {k: float(np.mean([m[k] for m in per_clip.values()])) for k in next(iter(per_clip.values()))}
    metrics.update(_compression(tok, first[0], first[2], codes))
    metrics.update(
        {"clips_scored": len(per_clip), "split": split, "model": str(model_dir), "skipped": skipped, "clips": per_clip}
    )
    write_json(out_dir / "metrics.json", metrics)
    save_side_by_side(first[0], first[1], out_dir / "side_by_side.png")
    return metrics


def _compression(tok: Tokenizer, video: torch.Tensor, latents: torch.Tensor, codes: list[torch.Tensor]) -> dict:
    out = {"compression_ratio": video[0].numel() / latents[0].numel()}
    if codes:
        used = torch.cat(codes).unique().numel()
        size = tok.quantizer.codebook_size
        out["codebook_usage"] = used / size
        out["bits_per_pixel"] = (
            latents[0, 0].numel() * math.log2(size) / (video.shape[2] * video.shape[3] * video.shape[4])
        )
    return out


def save_side_by_side(video: torch.Tensor, recon: torch.Tensor, path: str | Path, max_views: int = 3) -> Path:
    """PNG: per view (rows), input | reconstruction | |error| x4 at the first, middle, last frame."""
    if video.shape != recon.shape:
        raise DrivewmError(f"side-by-side needs equal shapes, got {tuple(video.shape)} and {tuple(recon.shape)}")
    rows = []
    for v in range(min(max_views, video.shape[0])):
        a, b = to_uint8(video[v]), to_uint8(recon[v])
        err = np.clip(np.abs(a.astype(np.int16) - b.astype(np.int16)) * 4, 0, 255).astype(np.uint8)
        t_sel = sorted({0, a.shape[0] // 2, a.shape[0] - 1})
        rows.append(np.concatenate([np.concatenate([a[t], b[t], err[t]], 1) for t in t_sel], 1))
    with atomic_path(path) as tmp:
        Image.fromarray(np.concatenate(rows, 0)).save(tmp, format="PNG")
    return Path(path)
