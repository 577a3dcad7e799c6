"""The AR generator: Video2World continuation of real frames and rollouts of any length in chunks, under a
chosen ego trajectory, from an AR model folder (drivewm.ar.folder) and its FSQ tokenizer.

A window is at most the model's context (``max_frames`` latent frames). Video2World encodes the given
frames, keeps them as the window's first latent frames and samples the rest token by token with the KV
cache (drivewm.ar.sampling). A rollout chains windows: each later window starts from the last frame
generated so far, decoded to pixels and encoded again as an image (the causal tokenizer codes a window's
first latent frame from one frame alone, so the model sees what it was trained on), with the trajectory
handed to each window in that window's first ego frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np
import torch

from drivewm.ar.folder import load_ar_folder
from drivewm.ar.model import ARCondition
from drivewm.ar.order import from_sequence, to_sequence
from drivewm.ar.sampling import sample_tokens
from drivewm.ar.sampling_config import TokenSampling
from drivewm.ar.tokens import fsq_levels, latent_frame_poses
from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.text import build_text_encoder
from drivewm.tokenizer.model import Tokenizer
from drivewm.views.rays import plucker_rays


class ARGenerator:
    """Video2World and rollouts with one AR model folder. Videos are (V, 3, T, H, W) in [-1, 1], V views in
    rig order; ``T_world_from_ego`` (T, 4, 4) per video frame."""

    def __init__(self, model_dir: str | Path, device: str | torch.device = "cpu"):
        self.model, self.cfg, tokenizer_dir = load_ar_folder(model_dir)
        self.tokenizer_dir = tokenizer_dir
        self.model.to(device)
        self.tokenizer = Tokenizer.from_pretrained(tokenizer_dir).to(device)
        fsq_levels(to_dict(self.tokenizer.config), str(tokenizer_dir))
        self.text = build_text_encoder(self.cfg.text)
        self.device = torch.device(device)

    @property
    def frames_per_latent(self) -> int:
        return self.tokenizer.config.temporal_compression

    def window_video_frames(self) -> int:
        """Video frames of a full window (1 + (max_frames - 1) * f, e.g. 17)."""
        return 1 + (self.cfg.ar.max_frames - 1) * self.frames_per_latent

    @torch.no_grad()
    def encode(self, video: torch.Tensor) -> torch.Tensor:
        """(V, 3, T, H, W) -> token grids (V, t, h, w)."""
        return self.tokenizer.indices(self.tokenizer.encode(video.to(self.device)))

    @torch.no_grad()
    def decode(self, tokens: torch.Tensor) -> torch.Tensor:
        """Token grids (V, t, h, w) -> (V, 3, T, H, W) in [-1, 1]."""
        return self.tokenizer.decode(self.tokenizer.quantizer.indices_to_codes(tokens)).clamp(-1, 1)

    def condition(self, caption: str, rig: Rig, T_world_from_ego: np.ndarray, frames: int) -> ARCondition:
        """The condition of every view of a window of ``frames`` latent frames starting at video frame 0 of
        ``T_world_from_ego``."""
        views = len(rig.cameras)
        emb, mask = self.text.encode([caption] * views)
        rays = plucker_rays(rig, tuple(self.cfg.ar.grid_hw))  # (V, h*w, 6)
        ego = latent_frame_poses(T_world_from_ego, self.frames_per_latent, frames)[None].expand(views, -1, -1)
        fps = torch.full((views,), self.cfg.fps)
        return ARCondition(emb, mask, rays, ego.contiguous(), fps).to(self.device)

    def video2world(
        self,
        video: torch.Tensor,
        caption: str,
        rig: Rig,
        T_world_from_ego: np.ndarray,
        sampling: TokenSampling,
        seed: int,
    ) -> torch.Tensor:
        """Continue ``video`` (V, 3, 1 + k*f, H, W) to a full window: (V, 3, window_video_frames, H, W),
        the given frames' reconstruction first. ``T_world_from_ego`` covers the window's video frames."""
        given = self.encode(video)  # (V, k+1, h, w)
        total = self.cfg.ar.max_frames
        if given.shape[1] >= total:
            raise DrivewmError(
                f"ar: {video.shape[2]} given frames fill the model's context of {total} latent frames; give fewer"
            )
        self.check_grid(given)
        cond = self.condition(caption, rig, T_world_from_ego, total)
        prompt = to_sequence(given, self.cfg.ar)  # (V, (k+1)*h*w)
        new = (total - given.shape[1]) * self.cfg.ar.frame_tokens
        generator = torch.Generator().manual_seed(seed)
        tokens = sample_tokens(self.model, cond, prompt, new, sampling, generator)
        return self.decode(from_sequence(tokens, self.cfg.ar))

    def rollout(
        self,
        first_frame: torch.Tensor,
        caption: str,
        rig: Rig,
        T_world_from_ego: np.ndarray,
        chunks: int,
        sampling: TokenSampling,
        seed: int,
    ) -> list[torch.Tensor]:
        """``chunks`` windows from ``first_frame`` (V, 3, 1, H, W): each (V, 3, window_video_frames, H, W),
        chunk k's first frame the last of chunk k-1. ``T_world_from_ego`` covers every video frame
        (1 + chunks * (window_video_frames - 1))."""
        step = self.window_video_frames() - 1
        if len(T_world_from_ego) < 1 + chunks * step:
            raise DrivewmError(
                f"ar rollout: {chunks} chunks need {1 + chunks * step} poses, got {len(T_world_from_ego)}"
            )
        out, frame = [], first_frame
        for k in range(chunks):
            poses = T_world_from_ego[k * step : k * step + step + 1]
            window = self.video2world(frame, caption, rig, poses, sampling, seed + k)
            out.append(window)
            frame = window[:, :, -1:]
        return out

    def check_grid(self, tokens: torch.Tensor) -> None:
        if list(tokens.shape[2:]) != list(self.cfg.ar.grid_hw):
            raise DrivewmError(
                f"ar: frames give a {tuple(tokens.shape[2:])} token grid, "
                f"the model was trained on {self.cfg.ar.grid_hw}"
            )


class ARFolderGenerator:
    """drivewm.generate.protocol.Generator of AR model folders (``model_type: ar``): Video2World from a
    condition clip's first frames, and rollouts of ``rollout.windows`` chunks, under ``trajectory``."""

    model_type: ClassVar[str] = "ar"
    inputs: ClassVar[tuple[str, ...]] = ("condition_clip",)

    def __init__(self, gen: ARGenerator, folder: Path):
        self.gen, self.folder = gen, folder

    @classmethod
    def from_pretrained(cls, folder: Path, device: str) -> ARFolderGenerator:
        from drivewm.device import resolve_device

        return cls(ARGenerator(folder, resolve_device(device)), folder)

    def generate(self, request, cfg) -> list:
        """Every prompt continued from the condition clip's first 1 + f frames, ``num_samples`` times."""
        from drivewm.generate.rollout import load_clip

        if request.condition_clip is None:
            raise DrivewmError(f"{self.folder}: an AR model continues a clip; give --condition-clip CLIP")
        clip = load_clip(request.condition_clip)
        f = self.gen.frames_per_latent
        samples = []
        for i, prompt in enumerate(p for p in request.prompts for _ in range(cfg.num_samples)):
            poses = self.poses(clip, cfg, self.gen.window_video_frames())
            video = self.gen.video2world(
                clip_video(clip)[:, :, : 1 + f], prompt, clip.meta.get_rig(), poses, cfg.tokens, cfg.sampling.seed + i
            )
            samples.append(self.sample(video, clip, prompt, poses, cfg, cfg.sampling.seed + i))
        return samples

    def rollout(self, clip, cfg, prompt: str = ""):
        """``clip`` continued from its first frame for ``rollout.windows`` chunks."""
        step = self.gen.window_video_frames() - 1
        poses = self.poses(clip, cfg, 1 + cfg.rollout.windows * step)
        caption = prompt or clip.meta.caption
        chunks = self.gen.rollout(
            clip_video(clip)[:, :, :1],
            caption,
            clip.meta.get_rig(),
            poses,
            cfg.rollout.windows,
            cfg.tokens,
            cfg.sampling.seed,
        )
        video = torch.cat([chunks[0]] + [c[:, :, 1:] for c in chunks[1:]], dim=2)
        return self.sample(video, clip, caption, poses, cfg, cfg.sampling.seed, {"rollout_of": clip.key})

    def poses(self, clip, cfg, frames: int) -> np.ndarray:
        """(frames, 4, 4) T_world_from_ego of ``cfg.trajectory`` at the clip's frame rate and speed."""
        from drivewm.generate.rollout import initial_speed_mps, rollout_poses

        speed = cfg.rollout.speed_mps or initial_speed_mps(clip)
        speed = speed if np.isfinite(speed) else 10.0
        dt_s = 1.0 / clip.meta.fps
        return rollout_poses(cfg.trajectory, frames, dt_s, speed, (frames - 1) * dt_s)

    def sample(self, video: torch.Tensor, clip, caption: str, poses: np.ndarray, cfg, seed: int, extra=None):
        from drivewm.generate.writer import GeneratedSample
        from drivewm.multiview.trajectories import waypoints_from_poses

        frames = ((video.clamp(-1, 1) + 1) * 127.5).round().byte().permute(0, 2, 3, 4, 1).cpu().numpy()
        rig = clip.meta.get_rig()
        record = {"model": str(self.folder.resolve()), "prompt": caption, "seed": seed, "trajectory": cfg.trajectory}
        record.update({"tokens": to_dict(cfg.tokens), "post_processing": [], **(extra or {})})
        waypoints = waypoints_from_poses(poses, 0, len(poses) - 1)
        return GeneratedSample(frames, rig, caption, [caption] * len(rig.cameras), waypoints, 1 / clip.meta.fps, record)

    def write(self, samples: list, out_dir: Path, name: str = "generated") -> list[Path]:
        from drivewm.generate.writer import write_samples

        return write_samples(out_dir, samples, self.gen.cfg.fps, name=name)


def clip_video(clip) -> torch.Tensor:
    """All cameras of a clip as (V, 3, T, H, W) in [-1, 1] (rig order)."""
    from drivewm.tokenizer.data import to_model_range

    return torch.stack([to_model_range(clip.video(cam)) for cam in clip.meta.cameras])
