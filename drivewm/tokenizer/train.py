"""Tokenizer training as a task of the shared loop (drivewm.train.loop): resume, EMA, learning-rate
schedule, bf16 autocast, activation checkpointing, compile and DDP/FSDP2 all live there.

The run's config nests like the other stages' (``model`` / ``loss`` / ``data`` / ``train``) and is
built by :data:`RECIPES` (drivewm.recipe): ``drivewm tokenizer train --preset small
--set train.steps=2000``. Each training sample is a random crop (``data.frames`` frames of
``data.crop`` pixels) of one camera video of one clip; the crop is drawn from the sample's seed,
so a resumed run (and a run on W processes) trains exactly what an uninterrupted single process
trains. ``TOKDIR`` receives the model folder (``config.json`` + ``model.safetensors``: EMA weights
and the per-channel latent statistics), ``train_state.pt``, ``metrics.jsonl`` and
``samples/step_N.png`` (input | reconstruction of held-in crops).
"""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import torch
from torch import nn

from drivewm.config import to_dict
from drivewm.diffusion.generate import write_grid_png
from drivewm.errors import DrivewmError
from drivewm.tokenizer.adversarial import Adversary
from drivewm.tokenizer.data import CameraVideos, load_clips, to_model_range, to_uint8
from drivewm.tokenizer.layers import ResBlock
from drivewm.tokenizer.losses import TokenizerLoss
from drivewm.tokenizer.metrics import psnr
from drivewm.tokenizer.model import Tokenizer
from drivewm.tokenizer.recipe import TokenizerTrainConfig
from drivewm.train.checkpoint import load_weights
from drivewm.train.loop import TrainTask, train


class CropDataset:
    """Every (clip, camera) video of the training clips; sample i under seed s is a random crop of
    video i drawn from a generator seeded s (so batches are a function of the step)."""

    def __init__(self, videos: CameraVideos, frames: int, crop_hw: tuple[int, int]):
        self.videos, self.frames, self.crop_hw = videos, frames, crop_hw
        shortest = min(len(c.meta.timestamps_ns) for c in videos.clips)
        if frames > shortest:
            raise DrivewmError(f"training wants {frames} frames per sample but the shortest clip has {shortest}")

    def __len__(self) -> int:
        return len(self.videos)

    def crop(self, index: int, seed: int) -> torch.Tensor:
        """(3, frames, H, W) in [-1, 1]: a crop of video ``index`` at a position drawn from ``seed``."""
        rng = np.random.default_rng(seed)
        frames = self.videos.frames(index)
        (t_all, h_all, w_all, _), (ch, cw) = frames.shape, self.crop_hw
        if ch > h_all or cw > w_all:
            raise DrivewmError(f"crop {ch}x{cw} is larger than the clip frames {h_all}x{w_all}")
        t0 = int(rng.integers(t_all - self.frames + 1))
        y0, x0 = int(rng.integers(h_all - ch + 1)), int(rng.integers(w_all - cw + 1))
        return to_model_range(np.ascontiguousarray(frames[t0 : t0 + self.frames, y0 : y0 + ch, x0 : x0 + cw]))

    def batch(self, indices: list[int], seeds: list[int]) -> torch.Tensor:
        """(B, 3, frames, H, W) crops."""
        return torch.stack([self.crop(i, s) for i, s in zip(indices, seeds)])


class TokenizerTask(TrainTask):
    """drivewm.train.loop.TrainTask for the tokenizer: reconstruction loss (+ optional hinge GAN)."""

    def __init__(self, cfg: TokenizerTrainConfig, dataset: CropDataset):
        self.cfg = cfg
        self.dataset = dataset
        self.model = Tokenizer(cfg.model).train()
        if cfg.init:
            load_parent(self.model, cfg.init)
        elif self.model.linear is not None:  # a resumed run then loads its trained code over this fit
            self.model.linear.fit([self.model.patch(b) for b in self._crop_batches(cfg.data.linear_fit_batches, 2)])
        if cfg.freeze_encoder:  # the linear code's basis codes as well as decodes: it is part of the encoder
            for part in (self.model.encoder, self.model.linear):
                if part is not None:
                    part.requires_grad_(False)
        self.loss_fn = TokenizerLoss(cfg.loss)
        self.adversary = Adversary(cfg.train.lr, cfg.loss.discriminator_weights) if cfg.loss.adversarial > 0 else None
        self._last: tuple[torch.Tensor, torch.Tensor] | None = None  # (recon, video) of the last step, for the GAN
        self.steps_done = (
            0  # optimizer steps of the model so far (the adversarial term starts at loss.adversarial_start)
        )

    def blocks(self) -> list[nn.Module]:
        return [m for m in self.model.modules() if isinstance(m, ResBlock)]

    def num_samples(self) -> int:
        return len(self.dataset)

    def tokens_per_sample(self) -> int:
        """Latent positions (t * h * w) of one crop."""
        m, (h, w) = self.cfg.model, self.cfg.data.crop
        return (
            (1 + (self.cfg.data.frames - 1) // m.temporal_compression)
            * (h // m.spatial_compression)
            * (w // m.spatial_compression)
        )

    def loss(self, forward, indices: list[int], seeds: list[int], device: torch.device):
        video = self.dataset.batch(indices, seeds).to(device)  # (B, 3, T, H, W)
        recon, _ = forward(video)
        total, terms = self.loss_fn(recon, video)
        if self.adversary is not None and self.steps_done >= self.cfg.loss.adversarial_start:
            self.adversary.to(device)
            adv = self.adversary.generator_loss(recon)
            total, terms["adversarial"] = total + self.cfg.loss.adversarial * adv, adv.item()
            self._last = (recon.detach(), video)
        return total, {**terms, "psnr": psnr(recon.detach().float(), video)}

    def after_step(self, step: int) -> dict[str, float]:
        """One discriminator update on the step's reconstructions (when the adversarial term is on)."""
        self.steps_done = step
        if self._last is None:
            return {}
        recon, video = self._last
        self._last = None
        return {"discriminator": self.adversary.discriminator_step(recon, video)}

    def extra_state(self) -> dict:
        state = {"steps_done": self.steps_done}
        return {**state, "adversary": self.adversary.state_dict()} if self.adversary is not None else state

    def load_extra_state(self, state: dict) -> None:
        self.steps_done = int(state.get("steps_done", 0))
        if self.adversary is not None and "adversary" in state:
            self.adversary.load_state_dict(state["adversary"])

    def shipped_model(self, ema_state: dict[str, torch.Tensor]) -> Tokenizer:
        """A frozen tokenizer with the EMA weights and latent statistics measured on training crops."""
        model = copy.deepcopy(self.model)  # frozen parameters and buffers are the live model's
        model.load_state_dict(ema_state, strict=False)  # the EMA holds the trained parameters
        model.requires_grad_(False).eval()
        if not self.cfg.freeze_encoder:  # a frozen encoder keeps the statistics every latent cache was normalised by
            set_latent_stats(model, self._stats_batches())
        return model

    def _stats_batches(self) -> list[torch.Tensor]:
        return self._crop_batches(self.cfg.data.stats_batches, 1)

    def _crop_batches(self, n: int, seed_offset: int) -> list[torch.Tensor]:
        """``n`` fixed batches of training crops drawn from ``train.seed + seed_offset``."""
        b = self.cfg.train.batch_size
        gen = torch.Generator().manual_seed(self.cfg.train.seed + seed_offset)
        return [
            self.dataset.batch(
                torch.randint(len(self.dataset), (b,), generator=gen).tolist(), [i * b + j for j in range(b)]
            )
            for i in range(n)
        ]

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        self.shipped_model(ema_state).save_pretrained(out_dir)

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        model = copy.deepcopy(self.model)
        model.load_state_dict(ema_state, strict=False)
        video = self._stats_batches()[0][:4]
        with torch.no_grad():
            recon = model.eval()(video)[0].clamp(-1, 1)
        rows = np.stack([to_uint8(torch.cat([v, r], dim=-1)) for v, r in zip(video, recon)])  # input | output
        write_grid_png(rows, path, ["input | reconstruction"] * len(rows))


@torch.no_grad()
def load_parent(model: Tokenizer, path: str | Path) -> None:
    """``init``: the parent tokenizer at ``path`` into ``model``. The model may have more decoder mid
    blocks than the parent (``--set model.decoder_mid_blocks=N``: a deeper decoder on the parent's
    latent space, with ``freeze_encoder``). The parent's blocks come first and each added one starts
    as the identity (the last convolution of its residual branch zero, bias included), so the
    step-0 model decodes exactly as the parent. Any other difference raises, as a strict load does."""
    parent = Tokenizer.from_pretrained(path)
    state = parent.state_dict()
    have = parent.config.decoder_mid_blocks
    if (
        model.config.decoder_mid_blocks > have
        and dataclasses.replace(model.config, decoder_mid_blocks=have) == parent.config
    ):
        for block in model.decoder.mid[have:]:
            block.start_as_identity()
        state = {**model.state_dict(), **state}  # the parent's weights, and the added blocks' own
    load_weights(model, state, path)


@torch.no_grad()
def set_latent_stats(model: Tokenizer, batches: list[torch.Tensor]) -> None:
    """Measure the per-channel mean and std of the latents of ``batches`` (each (B, 3, T, H, W))."""
    latents = torch.cat([model.encode(b).transpose(0, 1).flatten(1) for b in batches], 1)  # (c, N)
    model.latent_mean.copy_(latents.mean(1))
    model.latent_std.copy_(latents.std(1).clamp_min(1e-6))


def tokenizer_train(
    cfg: TokenizerTrainConfig, clip_dir: str | Path, out_dir: str | Path, stop_after: int | None = None
) -> dict:
    """Train (or resume) a tokenizer on the clips in ``clip_dir`` into ``out_dir``; returns the last metrics row."""
    videos = CameraVideos(load_clips(clip_dir, "train", cfg.data.holdout_percent))
    dataset = CropDataset(videos, cfg.data.frames, tuple(cfg.data.crop))
    torch.manual_seed(cfg.train.seed)  # the network's initial weights
    task = TokenizerTask(cfg, dataset)
    return train(task, cfg.train, out_dir, config_record=to_dict(cfg), stop_after=stop_after)
