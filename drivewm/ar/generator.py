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

import numpy as np
import torch

from drivewm.ar.folder import ARModelConfig, load_ar_folder
from drivewm.ar.model import ARCondition, ARTransformer
from drivewm.ar.order import from_sequence, to_sequence
from drivewm.ar.sampling import SamplingConfig, sample_tokens
from drivewm.ar.tokens import fsq_levels, latent_frame_poses
from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.multiview.camera import plucker_rays
from drivewm.text import build_text_encoder
from drivewm.tokenizer.model import Tokenizer


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
        sampling: SamplingConfig,
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
        sampling: SamplingConfig,
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


@torch.no_grad()
def write_sample_grid(
    cfg: ARModelConfig, state: dict[str, torch.Tensor], tokenizer_dir: Path, dataset, path: Path
) -> None:
    """A PNG of one sampled latent frame per caption of the first two dataset samples (training previews)."""
    from PIL import Image

    from drivewm.ar.train import batch_of
    from drivewm.atomic import atomic_path

    with torch.random.fork_rng():
        model = ARTransformer(cfg.ar)
    model.load_state_dict(state)
    model.eval()
    samples = [dataset[i] for i in range(min(2, len(dataset)))]
    _, cond = batch_of(samples, build_text_encoder(cfg.text), cfg.ar)
    empty = torch.zeros(len(samples), 0, dtype=torch.long)
    tokens = sample_tokens(model, cond, empty, cfg.ar.frame_tokens, SamplingConfig(), torch.Generator().manual_seed(0))
    tokenizer = Tokenizer.from_pretrained(tokenizer_dir)
    video = tokenizer.decode(tokenizer.quantizer.indices_to_codes(from_sequence(tokens, cfg.ar))).clamp(-1, 1)
    image = ((video[:, :, 0].permute(0, 2, 3, 1).flatten(0, 1) + 1) * 127.5).round().byte().numpy()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
