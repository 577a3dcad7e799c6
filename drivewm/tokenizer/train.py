"""Train a tokenizer on clip shards: AdamW with warm-up, gradient clipping, EMA, exact resume.

``TOKDIR`` receives the model folder (``config.json`` + ``model.safetensors``: EMA weights and
the per-channel latent statistics), ``train_state.pt`` (model, EMA, optimizer, step, config),
``train_config.json`` and ``metrics.jsonl``. Batches are drawn from (seed, step) and the
learning rate depends on the step alone, so a run that is stopped and started again, even with
a larger ``steps``, continues exactly as an uninterrupted run would.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import time
from pathlib import Path

import torch
from tqdm import tqdm

from drivewm.atomic import write_json
from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.tokenizer.adversarial import Adversary
from drivewm.tokenizer.config import TokenizerConfig, preset
from drivewm.tokenizer.data import CameraVideos, CropSampler, load_clips
from drivewm.tokenizer.losses import LossConfig, TokenizerLoss
from drivewm.tokenizer.metrics import psnr
from drivewm.tokenizer.model import Tokenizer
from drivewm.train.checkpoint import load_train_state, save_train_state
from drivewm.train.ema import EMA


@dataclasses.dataclass
class TokenizerTrainConfig:
    """A tokenizer training run."""

    model: TokenizerConfig = dataclasses.field(default_factory=lambda: preset("debug"))
    """The network (start from a preset: ``drivewm.tokenizer.config.PRESETS``)."""
    loss: LossConfig = dataclasses.field(default_factory=LossConfig)
    """Loss weights."""
    steps: int = 300
    """Total optimizer steps (a resumed run continues up to this)."""
    batch_size: int = 4
    """Videos per step (random camera videos of random clips)."""
    frames: int = 9
    """Frames per training video, 1 + k * temporal_compression."""
    crop: list[int] = dataclasses.field(default_factory=lambda: [64, 96])
    """Random crop [height, width] in pixels, multiples of the spatial compression."""
    lr: float = 1e-3
    """AdamW peak learning rate (constant after warm-up, so extending a run changes nothing before)."""
    warmup_steps: int = 20
    """Linear warm-up steps."""
    weight_decay: float = 0.0
    """AdamW weight decay."""
    grad_clip: float = 1.0
    """Global gradient-norm clip (0 = off)."""
    ema_decay: float = 0.99
    """EMA decay of the shipped weights (ramped up as min(d, (1+step)/(10+step)))."""
    seed: int = 0
    """Seeds initialization and every batch."""
    holdout_percent: int = 10
    """Clips held out from training by key hash (``drivewm tokenizer eval --split holdout`` scores them)."""
    checkpoint_every: int = 100
    """Write the training state every this many steps (and at the end)."""
    stats_batches: int = 4
    """Batches encoded after training to measure the per-channel latent mean and std."""
    log_every: int = 10
    """Append to metrics.jsonl every this many steps."""

    def validate(self) -> None:
        f, s = self.model.temporal_compression, self.model.spatial_compression
        if (self.frames - 1) % f:
            raise DrivewmError(f"train config: frames={self.frames} must be 1 + k*{f} for this model")
        if len(self.crop) != 2 or self.crop[0] % s or self.crop[1] % s:
            raise DrivewmError(f"train config: crop {self.crop} must be [height, width], multiples of {s}")


def ema_model(model: Tokenizer, ema: EMA) -> Tokenizer:
    """A frozen copy of ``model`` carrying the EMA weights (the weights the model folder ships)."""
    shipped = copy.deepcopy(model).requires_grad_(False).eval()
    shipped.load_state_dict(ema.state_dict(), strict=False)  # the EMA holds parameters; buffers are the model's
    return shipped


def learning_rate(cfg: TokenizerTrainConfig, step: int) -> float:
    return cfg.lr * min(1.0, (step + 1) / max(1, cfg.warmup_steps))


def train(clip_dir: str | Path, out_dir: str | Path, cfg: TokenizerTrainConfig, progress: bool = True) -> dict:
    """Train (or resume) a tokenizer on the clips in ``clip_dir``; returns a summary dict."""
    cfg.validate()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    videos = CameraVideos(load_clips(clip_dir, "train", cfg.holdout_percent))
    sampler = CropSampler(videos, cfg.frames, tuple(cfg.crop), cfg.seed)
    torch.manual_seed(cfg.seed)
    model = Tokenizer(cfg.model).train()
    ema = EMA(model, cfg.ema_decay)
    loss_fn = TokenizerLoss(cfg.loss)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, betas=(0.9, 0.99), weight_decay=cfg.weight_decay)
    adversary = Adversary(cfg.lr, cfg.loss.discriminator_weights) if cfg.loss.adversarial > 0 else None
    start = _resume(out_dir, cfg, model, ema, opt, adversary)
    write_json(out_dir / "train_config.json", to_dict(cfg))
    t0, terms = time.perf_counter(), {}
    for step in tqdm(
        range(start, cfg.steps), desc="tokenizer train", initial=start, total=cfg.steps, disable=not progress
    ):
        adv = adversary if adversary is not None and step >= cfg.loss.adversarial_start else None
        terms = _train_step(
            model, loss_fn, opt, sampler.batch(step, cfg.batch_size), learning_rate(cfg, step), cfg, adv
        )
        ema.update(model, step)
        if (step + 1) % cfg.log_every == 0 or step + 1 == cfg.steps:
            _log(out_dir, {"step": step + 1, "lr": learning_rate(cfg, step), **terms})
        if (step + 1) % cfg.checkpoint_every == 0:
            _save_state(out_dir, cfg, model, ema, opt, adversary, step + 1)
    _save_state(out_dir, cfg, model, ema, opt, adversary, max(start, cfg.steps))
    shipped = ema_model(model, ema)
    set_latent_stats(
        shipped, CropSampler(videos, cfg.frames, tuple(cfg.crop), cfg.seed + 1), cfg.stats_batches, cfg.batch_size
    )
    shipped.save_pretrained(out_dir, {"trained_steps": max(start, cfg.steps)})
    return {
        "steps": max(start, cfg.steps),
        "resumed_from": start,
        "seconds": time.perf_counter() - t0,
        "train_videos": len(videos),
        **terms,
    }


def _train_step(
    model: Tokenizer,
    loss_fn: TokenizerLoss,
    opt: torch.optim.Optimizer,
    video: torch.Tensor,
    lr: float,
    cfg: TokenizerTrainConfig,
    adversary: Adversary | None,
) -> dict[str, float]:
    for group in opt.param_groups:
        group["lr"] = lr
    recon, _ = model(video)  # (B, 3, T, H, W)
    total, terms = loss_fn(recon, video)
    if adversary is not None:
        adv = adversary.generator_loss(recon)
        total, terms["adversarial"] = total + cfg.loss.adversarial * adv, adv.item()
    opt.zero_grad(set_to_none=True)
    total.backward()
    if cfg.grad_clip > 0:
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
    opt.step()
    if adversary is not None:
        terms["discriminator"] = adversary.discriminator_step(recon, video)
    return {"loss": total.item(), **terms, "psnr": psnr(recon.detach(), video)}


@torch.no_grad()
def set_latent_stats(model: Tokenizer, sampler: CropSampler, batches: int, batch_size: int) -> None:
    """Measure the per-channel mean and std of the latents over ``batches`` random batches."""
    latents = torch.cat(
        [model.encode(sampler.batch(i, batch_size)).transpose(0, 1).flatten(1) for i in range(batches)], 1
    )
    model.latent_mean.copy_(latents.mean(1))
    model.latent_std.copy_(latents.std(1).clamp_min(1e-6))


def _save_state(out_dir: Path, cfg: TokenizerTrainConfig, model, ema: EMA, opt, adversary, step: int) -> None:
    state = {
        "step": step,
        "config": json.dumps(to_dict(cfg)),
        "model": model.state_dict(),
        "ema": ema.state_dict(),
        "optimizer": opt.state_dict(),
    }
    if adversary is not None:
        state["adversary"] = adversary.state_dict()
    save_train_state(out_dir, state)


def _resume(out_dir: Path, cfg: TokenizerTrainConfig, model, ema: EMA, opt, adversary) -> int:
    """Load the training state in ``out_dir`` if any; returns the step to start from."""
    state = load_train_state(out_dir)
    if state is None:
        return 0
    saved = json.loads(state["config"])
    if saved["model"] != to_dict(cfg.model):
        raise DrivewmError(
            f"{out_dir}: holds a training run of a different model config; use a new --out or the same preset"
        )
    model.load_state_dict(state["model"])
    ema.load_state_dict(state["ema"])
    opt.load_state_dict(state["optimizer"])
    if adversary is not None and "adversary" in state:
        adversary.load_state_dict(state["adversary"])
    return int(state["step"])


def _log(out_dir: Path, row: dict) -> None:
    with open(out_dir / "metrics.jsonl", "a") as f:
        f.write(json.dumps(row) + "\n")
