"""The Text2World generator: prompts -> latents -> video via the tokenizer (single-view clips)."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import torch
from tqdm import tqdm

from drivewm.clips.format import Clip
from drivewm.diffusion.generate import decode_latents, warn_if_preview
from drivewm.diffusion.text2world import Text2World
from drivewm.errors import DrivewmError
from drivewm.generate.config import GenerateConfig
from drivewm.generate.protocol import GenerateRequest
from drivewm.generate.writer import GeneratedSample, write_single_view
from drivewm.geometry import rig_from_dict

#: GenerateConfig fields only multi-view models read, with the value that means "not asked for".
MULTIVIEW_ONLY = {"rig": None, "trajectory": "straight", "post_processing": []}


class Text2WorldGenerator:
    """Samples a Text2World model folder (``model_type: text2world``)."""

    model_type: ClassVar[str] = "text2world"
    inputs: ClassVar[tuple[str, ...]] = ()

    def __init__(self, model: Text2World, folder: Path):
        self.model, self.folder = model, folder

    @classmethod
    def from_pretrained(cls, folder: Path, device: str) -> Text2WorldGenerator:
        return cls(Text2World.from_pretrained(folder).to(device), folder)

    def generate(self, request: GenerateRequest, cfg: GenerateConfig) -> list[GeneratedSample]:
        """``cfg.num_samples`` clips per prompt, ``cfg.batch_size`` denoised together."""
        check_single_view(self.folder, cfg)
        warn_if_preview(self.folder, self.model.latent.tokenizer)
        s = cfg.sampling
        prompts = [p for p in request.prompts for _ in range(cfg.num_samples)]
        seeds = [s.seed + i for i in range(len(prompts))]
        latents = []
        for start in tqdm(range(0, len(prompts), cfg.batch_size), desc="generate"):
            part = slice(start, start + cfg.batch_size)
            z = self.model.sample_latents(
                prompts[part], seeds[part], s.steps, s.guidance, s.sampler, guidance_interval=s.interval()
            )
            latents.append(z)
        videos = decode_latents(torch.cat(latents), self.model.latent.tokenizer, self.model.device)
        rig = rig_from_dict(self.model.latent.rig, "model rig")
        model = str(self.folder.resolve())
        record = {"steps": s.steps, "guidance": s.guidance, "guidance_interval": s.record()["guidance_interval"]}
        record["post_processing"] = []
        return [
            GeneratedSample(v[None], rig, p, [p], None, 0.0, {"model": model, "prompt": p, "seed": seed, **record})
            for v, p, seed in zip(videos, prompts, seeds)
        ]

    def rollout(self, clip: Clip, cfg: GenerateConfig, prompt: str = "") -> GeneratedSample:
        raise DrivewmError(f"{self.folder}: a Text2World model cannot roll out a clip (multi-view models do)")

    def write(self, samples: list[GeneratedSample], out_dir: Path, name: str = "generated") -> list[Path]:
        return write_single_view(out_dir, samples, self.model.latent.fps)


def check_single_view(folder: Path, cfg: GenerateConfig) -> None:
    """DrivewmError when ``cfg`` asks a Text2World model for what only multi-view models do."""
    asked = [k for k, off in MULTIVIEW_ONLY.items() if getattr(cfg, k) != off]
    asked += ["sampling.trajectory_guidance"] if cfg.sampling.trajectory_guidance != 1.0 else []
    if asked:
        raise DrivewmError(f"{folder}: a Text2World model takes no {', '.join(asked)} (multi-view models do)")
