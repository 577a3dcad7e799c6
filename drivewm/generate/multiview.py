"""The multi-view generator: prompts, a rig and a trajectory -> clips of all cameras (clip format),
grid videos and a contact sheet, for model folders of ``model_type: multiview``.

The generator builds every conditioning input (per-view captions, rig, waypoints, a condition
clip's latents) and hands them to :meth:`drivewm.multiview.model.MultiView.sample_latents`. With a
``condition_clip`` the first frames of every view come from a real clip (Video2World) and the
clip's rig calibration is used; without it, everything is generated. The opt-in post-steps
(:data:`drivewm.generate.config.POST_STEPS`) run after the network's sampling and are recorded
in every clip's ``post_processing``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch
from tqdm import tqdm

from drivewm.clips.format import Clip
from drivewm.diffusion.generate import warn_if_preview
from drivewm.errors import DrivewmError
from drivewm.generate.captions import template_view_captions, view_captions
from drivewm.generate.config import GenerateConfig
from drivewm.generate.protocol import GenerateRequest
from drivewm.generate.reproject import refine_reprojected
from drivewm.generate.rollout import clip_rig, initial_speed_mps, load_clip, rollout
from drivewm.generate.writer import GeneratedSample, write_samples
from drivewm.geometry import Rig, load_rig
from drivewm.layout.sources import (
    LayoutSource,
    layout_frames,
    layouts_from_clips,
    layouts_from_scenario,
    scenario_config,
)
from drivewm.multiview.coding import decode_views, encode_views
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectories import resample_waypoints, resolve_trajectory
from drivewm.tokenizer import Tokenizer
from drivewm.views.blend import blend_overlaps, stitch_views


@dataclasses.dataclass
class Conditions:
    """What conditions every sample of one ``generate`` run."""

    rig: Rig
    waypoints: np.ndarray
    """(W, 3) m in the first ego frame, spaced ``trajectory_dt_s``."""
    speed_mps: float
    cond_latents: torch.Tensor | None
    """(1, V, c, t, h, w) raw latents of a condition clip's first frames (Video2World); None: none."""
    layout_latents: torch.Tensor | None = None
    """(1, V, c, t, h, w) raw latents of the window's layout video in the rig (drivewm.layout); None: none."""


class MultiViewGenerator:
    """Samples a multi-view model folder: :meth:`generate` from prompts, :meth:`rollout` of a clip."""

    model_type: ClassVar[str] = "multiview"
    inputs: ClassVar[tuple[str, ...]] = ("condition_clip", "layout", "scenario")

    def __init__(self, model: MultiView, folder: Path):
        self.model, self.folder = model, folder
        self._tokenizer: Tokenizer | None = None

    @classmethod
    def from_pretrained(cls, folder: Path, device: str) -> MultiViewGenerator:
        return cls(MultiView.from_pretrained(folder).to(device), folder)

    @property
    def tokenizer(self) -> Tokenizer:
        """The model's tokenizer on its device (loaded once; a DrivewmError when none is recorded)."""
        if self._tokenizer is None:
            if not self.model.latent.tokenizer:
                raise DrivewmError(f"{self.folder}: no tokenizer recorded in the model folder; this needs one")
            self._tokenizer = Tokenizer.from_pretrained(self.model.latent.tokenizer).to(self.model.device)
        return self._tokenizer

    def conditions(self, request: GenerateRequest, cfg: GenerateConfig) -> Conditions:
        """Rig, trajectory, speed and condition latents of a run (a condition clip brings its rig and speed)."""
        mv = self.model.cfg.multiview
        rig = load_rig(cfg.rig) if cfg.rig else None
        cond, speed = None, mv.speed_mps
        if request.condition_clip is not None:
            cond, rig, clip_speed = self.condition_latents(Path(request.condition_clip), rig)
            speed = clip_speed if np.isfinite(clip_speed) else speed
        rig = rig or self.model.training_rig
        waypoints = resolve_trajectory(cfg.trajectory, mv.trajectory_waypoints, mv.trajectory_dt_s, speed)
        return Conditions(rig, waypoints, speed, cond)

    def condition_latents(self, clip_path: Path, rig: Rig | None) -> tuple[torch.Tensor, Rig, float]:
        """Raw latents (1, V, c, t, h, w) of a real clip's first frames (Video2World), its rig, its speed."""
        clip = load_clip(clip_path)
        rig = clip_rig(self.model, clip) if rig is None else clip.meta.get_rig().subset(rig.names)
        c, t, h, w = self.model.latent.latent_shape
        tc = self.tokenizer.config.temporal_compression
        sc = self.tokenizer.config.spatial_compression
        frames = np.stack([clip.video(n)[: 1 + (t - 1) * tc] for n in rig.names])
        z = encode_views(self.tokenizer, frames, (h * sc, w * sc), self.model.device)
        return z[None], rig, initial_speed_mps(clip)

    def generate(self, request: GenerateRequest, cfg: GenerateConfig) -> list[GeneratedSample]:
        """``cfg.num_samples`` clips per prompt of ``request`` (and per layout window, with a layout);
        sample i draws its noise from seed + i."""
        check_post_steps(request, cfg)
        warn_if_preview(self.folder, self.model.latent.tokenizer)
        prompts = [p for p in request.prompts for _ in range(cfg.num_samples)]
        if request.layout is not None or request.scenario is not None:
            return self.generate_from_layouts(request, cfg, prompts)
        cond = self.conditions(request, cfg)
        jobs = [(p, cfg.sampling.seed + i) for i, p in enumerate(prompts)]
        return [self.sample(prompt, seed, cond, request, cfg) for prompt, seed in tqdm(jobs, desc="generate")]

    def generate_from_layouts(
        self, request: GenerateRequest, cfg: GenerateConfig, prompts: list[str]
    ) -> list[GeneratedSample]:
        """Every layout window of ``request`` in every prompt's condition, along the window's own ego path
        (the layout is drawn along it), each clip keeping the window's pair id for the truth benchmark."""
        if self.model.cfg.multiview.layout == "none":
            raise DrivewmError(f"{self.folder}: this multi-view model was not trained with a layout (multiview.layout)")
        if request.condition_clip is not None:
            raise DrivewmError("generate: --layout/--scenario regenerate whole drives; give no --condition-clip")
        sources = self.layout_sources(request, cfg)
        rig = load_rig(cfg.rig) if cfg.rig else self.model.training_rig
        jobs = [(s, p) for s in sources for p in prompts]
        out = []
        for i, (source, prompt) in enumerate(tqdm(jobs, desc="generate from layouts")):
            cond, seed = self.layout_conditions(rig, source), cfg.sampling.seed + i
            sample = self.sample(prompt, seed, cond, request, cfg)
            sample.extra.update(layout=source.key, pair_id=source.pair_id, trajectory="layout", **source.tags)
            sample.layout = source.layout
            out.append(sample)
        return out

    def layout_sources(self, request: GenerateRequest, cfg: GenerateConfig) -> list[LayoutSource]:
        """The windows to generate: the ``--layout`` clips', or a ``--scenario`` simulated without pixels."""
        if request.layout is not None:
            if request.scenario is not None:
                raise DrivewmError("generate: give --layout or --scenario, not both")
            return layouts_from_clips(request.layout, cfg.layout_clips or None)
        t = self.model.latent.latent_shape[1]
        frames = 1 + (t - 1) * self.model.cfg.multiview.temporal_compression
        windows = cfg.layout_clips or 1
        fps = self.model.latent.fps  # one simulator tick per generated frame
        sim = scenario_config(request.scenario, cfg.sampling.seed, windows * frames / fps + 0.5, fps)
        return layouts_from_scenario(sim, frames, windows, self.model.cfg.multiview.trajectory_waypoints)

    def layout_conditions(self, rig: Rig, source: LayoutSource) -> Conditions:
        """The conditions of one layout window: its waypoints, speed and layout video's latents in ``rig``."""
        mv = self.model.cfg.multiview
        c, t, h, w = self.model.latent.latent_shape
        sc, tc = self.tokenizer.config.spatial_compression, self.tokenizer.config.temporal_compression
        frames = layout_frames(rig, source, (w * sc, h * sc), 1 + (t - 1) * tc)
        layout = encode_views(self.tokenizer, frames, (h * sc, w * sc), self.model.device)[None]
        waypoints = resample_waypoints(source.waypoints, mv.trajectory_waypoints)
        speed = float(np.linalg.norm(waypoints[0, :2]) / mv.trajectory_dt_s)
        return Conditions(rig, waypoints, speed, None, layout)

    def trajectory_conditions(self, rig: Rig, waypoints: np.ndarray, first_frames: np.ndarray | None) -> Conditions:
        """The conditions of one window along ``waypoints`` ((W, 3) m in its first ego frame, spaced
        ``trajectory_dt_s``) continuing ``first_frames`` (uint8 (V, n, H, W, 3), the window's first frames,
        Video2World as in drivewm.generate.rollout; None: every frame generated)."""
        mv = self.model.cfg.multiview
        waypoints = resample_waypoints(waypoints, mv.trajectory_waypoints)
        speed = float(np.linalg.norm(waypoints[0, :2]) / mv.trajectory_dt_s)
        if first_frames is None:
            return Conditions(rig, waypoints, speed, None)
        c, t, h, w = self.model.latent.latent_shape
        sc = self.tokenizer.config.spatial_compression
        z = encode_views(self.tokenizer, first_frames, (h * sc, w * sc), self.model.device)  # (V, c, t', h, w)
        cond = torch.zeros(len(rig.cameras), c, t, h, w)
        cond[:, :, : z.shape[2]] = z[:, :, :t]
        return Conditions(rig, waypoints, speed, cond[None])

    def sample(
        self, prompt: str, seed: int, cond: Conditions, request: GenerateRequest, cfg: GenerateConfig
    ) -> GeneratedSample:
        """One clip: the network's sampling, then the post-steps ``cfg`` asks for."""
        return self.sample_batch(prompt, [seed], [cond], request, cfg)[0]

    def sample_batch(
        self, prompt: str, seeds: list[int], conds: list[Conditions], request: GenerateRequest, cfg: GenerateConfig
    ) -> list[GeneratedSample]:
        """Clip b from ``conds[b]`` (one rig for all) and noise seed ``seeds[b]``, every clip in one denoiser
        batch, then each clip's post-steps. Noise is drawn per clip, so these are the clips of one call
        each, up to float rounding."""
        dt_s, rig = self.model.cfg.multiview.trajectory_dt_s, conds[0].rig
        if cfg.prompt_template:
            caps = [template_view_captions(prompt, c.rig, c.waypoints, dt_s) for c in conds]
        else:
            caps = [view_captions(prompt, c.rig) for c in conds]
        z = self.model.sample_latents(
            rig, caps, np.stack([c.waypoints for c in conds]), seeds, cfg.sampling.steps,
            cond_latents=_stacked([c.cond_latents for c in conds]),
            layout_latents=_stacked([c.layout_latents for c in conds]), **cfg.sampling.sample_kwargs(),
        )  # fmt: skip
        return [self._sampled(prompt, *clip, request, cfg) for clip in zip(seeds, conds, caps, z)]

    def _sampled(
        self, prompt: str, seed: int, cond: Conditions, caps: list[str], z: torch.Tensor, request: GenerateRequest,
        cfg: GenerateConfig,
    ) -> GeneratedSample:  # fmt: skip
        """One sampled clip's raw latents (V, c, t, h, w) decoded, post-stepped and recorded."""
        dt_s = self.model.cfg.multiview.trajectory_dt_s
        videos = self.decode(z)
        if cfg.post("reproject"):
            videos = self.reproject(videos, caps, cond, seed, cfg)
        if cfg.post("stitch"):
            videos = stitch_views(videos, cond.rig, self.model.cfg.multiview.warp_ground_m)
        extra = {
            "model": str(self.folder.resolve()),
            "prompt": prompt,
            "seed": seed,
            **cfg.record(),
            "trajectory": cfg.trajectory,
            "speed_mps": float(cond.speed_mps),
            "condition_clip": str(request.condition_clip or ""),
            "prompt_template": cfg.prompt_template,
        }
        return GeneratedSample(videos, cond.rig, prompt, caps, cond.waypoints, dt_s, extra)

    def decode(self, z: torch.Tensor) -> np.ndarray:
        """Raw latents (V, c, t, h, w) -> uint8 (V, T, H, W, 3) (a latent preview without a tokenizer)."""
        if not self.model.latent.tokenizer:
            from drivewm.diffusion.generate import latents_preview

            return latents_preview(z)
        return decode_views(self.tokenizer, z, self.model.device)

    def reproject(
        self, videos: np.ndarray, caps: list[str], cond: Conditions, seed: int, cfg: GenerateConfig
    ) -> np.ndarray:
        """The ``reproject`` post-step (drivewm.generate.reproject), the first frame blended first with ``blend``."""
        if cfg.post("blend"):
            videos = videos.copy()
            videos[:, 0] = blend_overlaps(videos[:, 0], cond.rig, self.model.cfg.multiview.warp_ground_m)
        z = refine_reprojected(
            self.model, self.tokenizer, cond.rig, caps, cond.waypoints, seed, videos, cfg.reproject,
            cfg.post("reshade"), cfg.sampling.sample_kwargs(),
        )  # fmt: skip
        return self.decode(z)

    def rollout(self, clip: Clip, cfg: GenerateConfig, prompt: str = "") -> GeneratedSample:
        """``clip`` continued for ``cfg.rollout.windows`` windows (drivewm.generate.rollout)."""
        if cfg.post("blend") or cfg.post("stitch"):
            raise DrivewmError(
                "rollout: a rollout's first frames are the clip's own; post_processing takes no blend/stitch"
            )
        return rollout(self.model, clip, cfg, self.tokenizer, prompt)

    def write(self, samples: list[GeneratedSample], out_dir: Path, name: str = "generated") -> list[Path]:
        return write_samples(out_dir, samples, self.model.latent.fps, name=name)


def _stacked(latents: list[torch.Tensor | None]) -> torch.Tensor | None:
    """Per clip (1, V, c, t, h, w) latents -> (B, V, c, t, h, w); None when no clip has any."""
    if all(z is None for z in latents):
        return None
    if any(z is None for z in latents):
        raise DrivewmError("sample_batch: give condition latents for every clip of a batch or for none")
    return torch.cat(latents)


def check_post_steps(request: GenerateRequest, cfg: GenerateConfig) -> None:
    """DrivewmError for blending a condition clip's frames (they are the clip's own and agree already)."""
    blended = [s for s in ("blend", "stitch") if cfg.post(s)]
    if blended and request.condition_clip is not None:
        raise DrivewmError(
            f"{request.condition_clip}: post_processing {blended} blends generated frames; a condition clip's "
            "frames are the clip's own and are never blended"
        )
