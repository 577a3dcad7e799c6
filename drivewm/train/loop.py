"""The training loop shared by pretraining and multi-view post-training.

What is trained is a :class:`TrainTask` (the model, how a batch of dataset indices becomes a
loss, how EMA weights become a model folder and a sample grid); the loop owns the rest: AdamW
with warm-up, gradient clipping, EMA, bf16 autocast on GPUs (fp32 on the CPU), parallelism via
drivewm.train.parallelize, ``metrics.jsonl``, periodic sample grids, and resumable checkpoints.

Exact resume and world-size independence come from making every random draw a function of
(seed, step, position in the global batch): the data order is a seeded permutation per epoch and
each sample gets its own noise seed, so the data position *is* the step, and rank r of W simply
takes its slice of the same global batch. A resumed run therefore equals an uninterrupted one,
and torchrun with W processes trains what one process trains with the same global batch.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import time
from collections.abc import Callable
from pathlib import Path
from typing import Literal, Protocol

import torch
import torch.distributed as dist
from torch import nn
from tqdm import tqdm

from drivewm.atomic import JsonlAppender
from drivewm.config import above, at_least, in_range, require
from drivewm.errors import DrivewmError
from drivewm.train.checkpoint import load_train_state, save_train_state
from drivewm.train.distributed import DistInfo, barrier, init_distributed, shutdown_distributed
from drivewm.train.ema import EMA
from drivewm.train.parallelize import Parallel, parallelize

METRICS_NAME = "metrics.jsonl"


@dataclasses.dataclass
class TrainConfig:
    """Optimisation and run settings (model and data settings live with the task)."""

    steps: int = 1000
    """Total optimizer steps of the run (a resumed run continues up to this)."""
    batch_size: int = 8
    """Global batch: samples per step summed over all ranks (must divide by the world size)."""
    lr: float = 3e-4
    """AdamW peak learning rate."""
    warmup_steps: int = 50
    """Linear learning-rate warm-up from 0."""
    weight_decay: float = 0.0
    """AdamW weight decay."""
    betas: list[float] = dataclasses.field(default_factory=lambda: [0.9, 0.99])
    """AdamW betas."""
    grad_clip: float = 1.0
    """Clip the global gradient norm to this (0 = off)."""
    ema_decay: float = 0.999
    """EMA decay of the shipped weights."""
    seed: int = 0
    """Seeds initialisation, data order and every per-sample draw."""
    log_every: int = 10
    """Steps between metrics.jsonl rows."""
    checkpoint_every: int = 200
    """Steps between checkpoints (model folder + train_state.pt); always at the end."""
    sample_every: int = 0
    """Steps between sample grids in OUT/samples/ (0 = only at the end)."""
    precision: Literal["auto", "fp32", "bf16"] = "auto"
    """``auto``: bf16 autocast on CUDA, fp32 on the CPU (bf16 is ~200x slower there)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """Where to train."""
    activation_checkpointing: bool = False
    """Recompute block activations in the backward pass (saves memory)."""
    compile: bool = False
    """torch.compile each block (20-45 s up front on this CPU, ~10% faster)."""
    parallel: Parallel = "auto"
    """Under torchrun: ``ddp`` (= auto) or ``fsdp`` (FSDP2, for large presets)."""

    def validate(self) -> None:
        at_least(self, 1, "steps", "batch_size", "log_every", "checkpoint_every")
        at_least(self, 0, "warmup_steps", "weight_decay", "grad_clip", "sample_every")
        above(self, 0, "lr")
        in_range(self, "ema_decay", 0, 1, high_open=True)
        require(
            len(self.betas) == 2 and all(0 <= b < 1 for b in self.betas), "betas", self.betas, "two numbers in [0, 1)"
        )


class TrainTask(Protocol):
    """What a stage gives the loop."""

    model: nn.Module
    """The module to train (e.g. an EDM denoiser around a DiT)."""

    def blocks(self) -> list[nn.Module]:
        """The repeated blocks (checkpointing, compile and FSDP apply per block)."""

    def num_samples(self) -> int:
        """Dataset size."""

    def tokens_per_sample(self) -> int:
        """Latent tokens per sample (throughput metric)."""

    def loss(
        self, forward: Callable[..., torch.Tensor], indices: list[int], seeds: list[int], device: torch.device
    ) -> torch.Tensor:
        """Mean loss of the samples ``indices``, sample i drawing its randomness from ``seeds[i]``;
        ``forward`` is the (possibly wrapped) model to call."""

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        """Write the model folder (config.json + model.safetensors) from EMA weights."""

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        """Write a PNG of samples from the EMA weights."""


def mix_seed(*parts: int) -> int:
    """A stable 63-bit seed from integers (blake2b), e.g. (seed, step, position)."""
    digest = hashlib.blake2b(",".join(map(str, parts)).encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") >> 1


def global_batch(step: int, batch_size: int, num_samples: int, seed: int) -> list[int]:
    """Dataset indices of the global batch at ``step``: epochs are seeded permutations."""
    positions = range(step * batch_size, (step + 1) * batch_size)
    return [int(_epoch_permutation(seed, pos // num_samples, num_samples)[pos % num_samples]) for pos in positions]


@functools.lru_cache(maxsize=4)
def _epoch_permutation(seed: int, epoch: int, num_samples: int) -> torch.Tensor:
    return torch.randperm(num_samples, generator=torch.Generator().manual_seed(mix_seed(seed, epoch)))


def learning_rate(cfg: TrainConfig, step: int) -> float:
    return cfg.lr * min(1.0, (step + 1) / max(1, cfg.warmup_steps))


@dataclasses.dataclass
class _Run:
    """The live objects of one run."""

    info: DistInfo
    model: nn.Module
    forward: nn.Module
    optimizer: torch.optim.Optimizer
    ema: EMA
    step: int = 0


def _setup(task: TrainTask, cfg: TrainConfig) -> _Run:
    info = init_distributed(cfg.device)
    if cfg.batch_size % info.world_size:
        raise DrivewmError(f"train.batch_size {cfg.batch_size} does not divide over {info.world_size} processes")
    model = task.model.to(info.device)
    forward = parallelize(model, task.blocks(), info, cfg.activation_checkpointing, cfg.compile, cfg.parallel)
    params = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=cfg.lr, betas=tuple(cfg.betas), weight_decay=cfg.weight_decay)
    return _Run(info, model, forward, optimizer, EMA(model, cfg.ema_decay))


def _state_dicts(run: _Run) -> tuple[dict, dict]:
    """Full (un-sharded, CPU) model and optimizer state dicts, keyed by parameter name."""
    from torch.distributed.checkpoint.state_dict import StateDictOptions, get_state_dict

    return get_state_dict(run.model, run.optimizer, options=StateDictOptions(full_state_dict=True, cpu_offload=True))


def _resume(run: _Run, out_dir: Path) -> None:
    from torch.distributed.checkpoint.state_dict import StateDictOptions, set_state_dict

    state = load_train_state(out_dir)
    if state is None:
        return
    set_state_dict(
        run.model,
        run.optimizer,
        model_state_dict=state["model"],
        optim_state_dict=state["optimizer"],
        options=StateDictOptions(full_state_dict=True),
    )
    run.ema.load_state_dict(state["ema"])
    run.step = int(state["step"])
    torch.set_rng_state(state["rng"]["torch"])


def _checkpoint(run: _Run, task: TrainTask, out_dir: Path, config_record: dict) -> None:
    """Model folder from the EMA weights + train_state.pt (every rank joins the gathers)."""
    model_sd, optim_sd = _state_dicts(run)
    ema_sd = run.ema.state_dict()
    if run.info.is_main:
        task.save_model(ema_sd, out_dir)
        save_train_state(
            out_dir,
            {
                "model": model_sd,
                "ema": ema_sd,
                "optimizer": optim_sd,
                "step": run.step,
                "data_position": run.step,
                "rng": {"torch": torch.get_rng_state()},
                "config": config_record,
            },
        )
    barrier(run.info)


def _metrics_file(out_dir: Path, start_step: int) -> JsonlAppender:
    """metrics.jsonl opened for appending, without rows past ``start_step`` (a resumed run rewrites them)
    and without a torn last row (a kill mid-append)."""
    return JsonlAppender(out_dir / METRICS_NAME, keep=lambda row: _row_step(row) <= start_step)


def _row_step(row: dict) -> float:
    step = row.get("step")
    return step if isinstance(step, int) else float("inf")


def _train_step(run: _Run, task: TrainTask, cfg: TrainConfig) -> tuple[float, float]:
    """One optimizer step on this rank's slice of the global batch; returns (mean loss, grad norm)."""
    info, step = run.info, run.step
    indices = global_batch(step, cfg.batch_size, task.num_samples(), cfg.seed)
    seeds = [mix_seed(cfg.seed, step, j) for j in range(cfg.batch_size)]
    local = slice(info.rank * cfg.batch_size // info.world_size, (info.rank + 1) * cfg.batch_size // info.world_size)
    for group in run.optimizer.param_groups:
        group["lr"] = learning_rate(cfg, step)
    use_bf16 = cfg.precision == "bf16" or (cfg.precision == "auto" and info.device.type == "cuda")
    with torch.autocast(info.device.type, dtype=torch.bfloat16, enabled=use_bf16):
        loss = task.loss(run.forward, indices[local], seeds[local], info.device)
    loss.backward()
    grad_norm = torch.nn.utils.clip_grad_norm_(
        run.model.parameters(), cfg.grad_clip if cfg.grad_clip > 0 else float("inf")
    )
    run.optimizer.step()
    run.optimizer.zero_grad(set_to_none=True)
    run.ema.update(run.model, step)
    run.step += 1
    mean_loss = loss.detach()
    if info.distributed:
        dist.all_reduce(mean_loss)  # SUM (gloo has no AVG)
        mean_loss /= info.world_size
    return float(mean_loss), float(grad_norm.full_tensor() if hasattr(grad_norm, "full_tensor") else grad_norm)


def train(
    task: TrainTask,
    cfg: TrainConfig,
    out_dir: str | Path,
    config_record: dict | None = None,
    stop_after: int | None = None,
) -> dict:
    """Train ``task`` into ``out_dir`` (model folder + train_state.pt + metrics.jsonl + samples/),
    resuming from ``out_dir/train_state.pt`` when present. ``stop_after``: leave after this many
    steps of *this* call (as if killed right after a checkpoint), for tests and time-boxed jobs.
    Returns the last metrics row."""
    cfg.validate()
    out_dir = Path(out_dir)
    torch.manual_seed(cfg.seed)
    run = _setup(task, cfg)
    _resume(run, out_dir)
    start, last = run.step, {}
    end = cfg.steps if stop_after is None else min(cfg.steps, start + stop_after)
    metrics = _metrics_file(out_dir, start) if run.info.is_main else None
    bar = tqdm(range(start, end), desc="train", disable=not run.info.is_main, initial=start, total=cfg.steps)
    busy_s, busy_steps = 0.0, 0  # training time since the last row (checkpoints and samples excluded)
    for _ in bar:
        tic = time.perf_counter()
        loss, grad_norm = _train_step(run, task, cfg)
        busy_s, busy_steps = busy_s + time.perf_counter() - tic, busy_steps + 1
        if run.step % cfg.log_every == 0 or run.step == end:
            last = {
                "step": run.step,
                "loss": loss,
                "grad_norm": grad_norm,
                "lr": learning_rate(cfg, run.step - 1),
                "tokens_per_s": task.tokens_per_sample() * cfg.batch_size * busy_steps / max(busy_s, 1e-9),
            }
            busy_s, busy_steps = 0.0, 0
            if metrics:
                metrics.write(last)
            bar.set_postfix(loss=f"{loss:.4f}")
        if run.step % cfg.checkpoint_every == 0 or run.step == end:
            _checkpoint(run, task, out_dir, config_record or {})
        if run.step == cfg.steps or (cfg.sample_every and run.step % cfg.sample_every == 0):
            ema_sd = run.ema.state_dict()  # a gather under FSDP: every rank joins
            if run.info.is_main:
                task.sample_grid(ema_sd, out_dir / "samples" / f"step_{run.step:07d}.png")
    if metrics:
        metrics.close()
    shutdown_distributed()
    return last
