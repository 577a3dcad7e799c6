"""Text2World generation: prompts -> latents -> video via the tokenizer -> clip shards, mp4, contact sheet.

Generated samples use the clip format (docs/DESIGN.md section 4) so drivewm.eval scores them like
real clips: ``GENDIR/generated-000000.tar`` + ``manifest.jsonl``, plus ``sample_XXX.mp4`` per
sample and ``contact_sheet.png``.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch
from einops import rearrange
from PIL import Image, ImageDraw
from tqdm import tqdm

from drivewm.atomic import atomic_path, write_bytes
from drivewm.clips.format import ClipMeta, clip_from_arrays
from drivewm.clips.shards import ShardWriter, write_manifest
from drivewm.clips.video import encode_mp4
from drivewm.config import check_guidance_interval, finite_at_least
from drivewm.diffusion.text2world import Text2World
from drivewm.errors import DrivewmError
from drivewm.tokenizer import Tokenizer


@dataclasses.dataclass
class GenerateOptions:
    """Sampling settings of ``drivewm generate`` (defaults: Cosmos' 35 steps, guidance 7)."""

    prompts: list[str]
    """One caption per sample group (each generated ``num_samples`` times)."""
    steps: int = 35
    """Sampler steps (Karras schedule, rho = 7)."""
    guidance: float = 7.0
    """Classifier-free guidance scale (1 = none)."""
    seed: int = 0
    """Sample i uses seed + i."""
    num_samples: int = 1
    """Samples per prompt."""
    sampler: str = "heun"
    """``heun`` (EDM Alg. 1) or ``euler``."""
    batch_size: int = 4
    """Samples denoised together."""
    device: str = "auto"
    """``auto`` (CUDA when available), ``cpu`` or ``cuda``."""
    guidance_interval: tuple[float, float] | None = None
    """Guide only at sigma in (lo, hi] (drivewm.diffusion.sampling); None: at every sigma."""

    def __post_init__(self) -> None:
        if not self.prompts or self.steps < 1 or self.num_samples < 1 or self.batch_size < 1:
            raise DrivewmError("generate: needs at least one prompt, steps >= 1 and num_samples >= 1")
        finite_at_least("generate", 0, **{"--guidance": self.guidance})
        self.guidance_interval = check_guidance_interval("generate", self.guidance_interval)

    def record(self) -> dict:
        """The sampling settings a generated clip's metadata keeps."""
        interval = list(self.guidance_interval) if self.guidance_interval else None
        return {"steps": self.steps, "guidance": self.guidance, "guidance_interval": interval}


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


def write_generated(
    out_dir: Path, videos: np.ndarray, prompts: list[str], rig: dict, fps: float, extras: list[dict]
) -> list[Path]:
    """Write clips (shards + manifest), one mp4 per sample and the contact sheet; returns the written files."""
    out_dir.mkdir(parents=True, exist_ok=True)
    camera = rig["cameras"][0]["name"]
    rows, files = [], []
    with ShardWriter(out_dir, "generated") as writer:
        for i, (video, prompt, extra) in enumerate(zip(videos, prompts, extras)):
            h, w = video.shape[1:3]
            rig_i = {**rig, "cameras": [{**rig["cameras"][0], "width": w, "height": h}]}
            meta = clip_meta(f"sample_{i:03d}", rig_i, fps, len(video), prompt, extra)
            writer.write(clip_from_arrays(meta, {camera: video}, np.tile(np.eye(4), (len(video), 1, 1))))
            write_bytes(out_dir / f"sample_{i:03d}.mp4", encode_mp4(video, fps))
            files.append(out_dir / f"sample_{i:03d}.mp4")
            rows.append({"key": meta.key, "caption": prompt, **extra})
    for (shard, _key), row in zip(writer.written, rows):
        row["shard"] = Path(shard).name
    files.append(write_manifest(out_dir, rows))
    files.append(write_grid_png(videos, out_dir / "contact_sheet.png", prompts))
    return files


def generate_text2world(model_dir: str | Path, options: GenerateOptions, out_dir: str | Path) -> list[Path]:
    """Sample ``options.num_samples`` clips per prompt from a Text2World folder and write them."""
    model = Text2World.from_pretrained(model_dir).to(options.device)
    warn_if_preview(model_dir, model.latent.tokenizer)
    prompts = [p for p in options.prompts for _ in range(options.num_samples)]
    seeds = [options.seed + i for i in range(len(prompts))]
    latents = []
    for start in tqdm(range(0, len(prompts), options.batch_size), desc="generate"):
        part = slice(start, start + options.batch_size)
        latents.append(
            model.sample_latents(
                prompts[part],
                seeds[part],
                options.steps,
                options.guidance,
                options.sampler,
                guidance_interval=options.guidance_interval,
            )
        )
    videos = decode_latents(torch.cat(latents), model.latent.tokenizer, model.device)
    extras = [
        {
            "model": str(Path(model_dir).resolve()),
            "prompt": p,
            "seed": s,
            **options.record(),
        }
        for p, s in zip(prompts, seeds)
    ]
    return write_generated(Path(out_dir), videos, prompts, model.latent.rig, model.latent.fps, extras)
