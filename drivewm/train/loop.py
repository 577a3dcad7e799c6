"""The training loop shared by pretraining and multi-view post-training.

What is trained is a :class:`TrainTask` (the model, how a batch of dataset indices becomes a
loss, how EMA weights become a model folder and a sample grid); the loop owns the rest: AdamW
with warm-up, gradient clipping, EMA, bf16 autocast on GPUs (fp32 on the CPU), parallelism via
drivewm.train.parallelize, ``metrics.jsonl``, periodic sample grids, and resumable checkpoints.

A step whose loss, gradient norm or logged term is NaN or infinite stops the run at once with a one-line
error naming the step, before the optimizer applies it and before anything is saved from it, so the run
folder keeps its last good checkpoint and a rerun (with a lower learning rate, say) resumes from there.

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
import math
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch
import torch.distributed as dist
from torch import nn
from tqdm import tqdm

from drivewm.atomic import JsonlAppender, remove_dead_temporaries
from drivewm.errors import DrivewmError
from drivewm.train.checkpoint import load_train_state, save_train_state
from drivewm.train.config import BUDGET_PROBE_STEPS, TrainConfig
from drivewm.train.distributed import DistInfo, barrier, init_distributed, shutdown_distributed
from drivewm.train.ema import EMA
from drivewm.train.parallelize import parallelize

METRICS_NAME = "metrics.jsonl"


class TrainTask:
    """What a stage gives the loop. Subclasses implement the first six methods; the last three are
    optional hooks (a second network trained beside the model, e.g. a GAN discriminator)."""

    model: nn.Module
    """The module to train (e.g. an EDM denoiser around a DiT)."""

    def blocks(self) -> list[nn.Module]:
        """The repeated blocks (checkpointing, compile and FSDP apply per block)."""
        raise NotImplementedError

    def num_samples(self) -> int:
        """Dataset size."""
        raise NotImplementedError

    def tokens_per_sample(self) -> int:
        """Latent tokens per sample (throughput metric)."""
        raise NotImplementedError

    def loss(
        self, forward: Callable[..., torch.Tensor], indices: list[int], seeds: list[int], device: torch.device
    ) -> torch.Tensor | tuple[torch.Tensor, dict[str, float]]:
        """Mean loss of the samples ``indices``, sample i drawing its randomness from ``seeds[i]``;
        ``forward`` is the (possibly wrapped) model to call. May also return named terms to log."""
        raise NotImplementedError

    def save_model(self, ema_state: dict[str, torch.Tensor], out_dir: Path) -> None:
        """Write the model folder (config.json + model.safetensors) from EMA weights."""
        raise NotImplementedError

    def sample_grid(self, ema_state: dict[str, torch.Tensor], path: Path) -> None:
        """Write a PNG of samples from the EMA weights."""
        raise NotImplementedError

    def lr_scales(self) -> dict[str, float]:
        """Learning-rate multipliers by parameter-name prefix (names in :attr:`model`, the first
        matching prefix wins); every other parameter trains at the schedule's rate."""
        return {}

    def after_step(self, step: int) -> dict[str, float]:
        """Called after every optimizer step of the model (``step`` = steps done); returns terms to log."""
        return {}

    def extra_state(self) -> dict:
        """Task state saved in train_state.pt beside the model's (tensors, numbers, dicts)."""
        return {}

    def load_extra_state(self, state: dict) -> None:
        """Restore :meth:`extra_state` on resume."""


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
    """Linear warm-up to ``cfg.lr``, then constant or a half cosine down to ``lr * min_lr_ratio``."""
    peak = max(0, cfg.warmup_steps - 1)  # the step that reaches cfg.lr
    if step < peak or cfg.lr_schedule == "constant":
        return cfg.lr * min(1.0, (step + 1) / max(1, cfg.warmup_steps))
    progress = min(1.0, (step - peak) / max(1, cfg.steps - 1 - peak))
    return cfg.lr * (cfg.min_lr_ratio + (1 - cfg.min_lr_ratio) * 0.5 * (1 + math.cos(math.pi * progress)))


def budget_steps(cfg: TrainConfig, done: int, spent_s: float, step_seconds: list[float]) -> int:
    """The step count a run with ``cfg.budget_minutes`` settles on after ``done`` steps and ``spent_s``
    seconds of training: what the rest of the budget holds at the median of ``step_seconds`` (the first
    two, warm-up of kernels and compilation, left out when there are more), at least ``done`` and at
    most ``cfg.steps``."""
    timed = step_seconds[2:] if len(step_seconds) > 2 else step_seconds
    per_step = max(statistics.median(timed), 1e-9)
    left = max(0.0, cfg.budget_minutes * 60 - spent_s)
    fits = done + int(left / per_step) if math.isfinite(left) else cfg.steps
    return max(done, min(cfg.steps, fits))


def adamw_impl(params: list[torch.Tensor]) -> str:
    """``fused`` (one kernel over all tensors) for plain CPU/CUDA parameters, ``foreach`` for FSDP2's DTensors.

    Measured by benchmarks/bench_optimizer.py: the fused step is several times faster than the
    per-tensor default on a CPU, with the same update up to rounding. DTensor shards take the
    foreach path, which torch supports for every placement.
    """
    plain = all(type(p) is torch.Tensor or type(p) is nn.Parameter for p in params)
    return "fused" if plain and all(p.device.type in ("cpu", "cuda") for p in params) else "foreach"


@dataclasses.dataclass
class _Run:
    """The live objects of one run."""

    info: DistInfo
    model: nn.Module
    forward: nn.Module
    optimizer: torch.optim.Optimizer
    ema: EMA
    step: int = 0
    train_seconds: float = 0.0
    """Wall seconds spent in training steps over the whole run, resumes included (compute spent)."""
    budget_steps: int | None = None
    """The step count a budgeted run settled on (``TrainConfig.budget_minutes``), once it has."""
    saved_step: int | None = None
    """The step of the newest checkpoint in the run folder (None before the first)."""


def _setup(task: TrainTask, cfg: TrainConfig) -> _Run:
    info = init_distributed(cfg.device)
    if cfg.batch_size % info.world_size:
        raise DrivewmError(f"train.batch_size {cfg.batch_size} does not divide over {info.world_size} processes")
    model = task.model.to(info.device)
    forward = parallelize(model, task.blocks(), info, cfg.activation_checkpointing, cfg.compile, cfg.parallel)
    params = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(
        param_groups(model, task.lr_scales()),
        lr=cfg.lr,
        betas=tuple(cfg.betas),
        weight_decay=cfg.weight_decay,
        **{adamw_impl(params): True},
    )
    return _Run(info, model, forward, optimizer, EMA(model, cfg.ema_decay))


def param_groups(model: nn.Module, scales: dict[str, float]) -> list[dict]:
    """AdamW parameter groups of ``model``'s trainable parameters, one per learning-rate multiplier
    (``lr_scale``, applied to the schedule's rate every step; :meth:`TrainTask.lr_scales`)."""
    groups: dict[float, list] = {}
    for name, p in model.named_parameters():
        if p.requires_grad:
            scale = next((v for prefix, v in scales.items() if name.startswith(prefix)), 1.0)
            groups.setdefault(float(scale), []).append(p)
    return [{"params": params, "lr_scale": scale} for scale, params in groups.items()]


def _rank0(info: DistInfo, value: int) -> int:
    """Rank 0's ``value`` on every rank (ranks time their own steps; the step count must agree)."""
    if not info.distributed:
        return value
    shared = torch.tensor([value], dtype=torch.int64, device=info.device)
    dist.broadcast(shared, src=0)
    return int(shared)


def _state_dicts(run: _Run) -> tuple[dict, dict]:
    """Full (un-sharded, CPU) model and optimizer state dicts, keyed by parameter name."""
    from torch.distributed.checkpoint.state_dict import StateDictOptions, get_state_dict

    return get_state_dict(run.model, run.optimizer, options=StateDictOptions(full_state_dict=True, cpu_offload=True))


def _check_same_model(model: nn.Module, saved: dict[str, torch.Tensor], out_dir: Path) -> None:
    """A resumed run must train the same network: same parameter names and shapes."""
    ours = {name: tuple(p.shape) for name, p in model.state_dict().items()}  # DTensors report full shapes
    theirs = {name: tuple(t.shape) for name, t in saved.items()}
    if ours != theirs:
        diff = sorted(set(ours.items()) ^ set(theirs.items()))[:3]
        raise DrivewmError(
            f"{out_dir}: holds a training run of a different model (differs at {diff}); "
            "use a new --out or the same config"
        )


def _resume(run: _Run, task: TrainTask, out_dir: Path) -> None:
    from torch.distributed.checkpoint.state_dict import StateDictOptions, set_state_dict

    state = load_train_state(out_dir)
    if state is None:
        return
    _check_same_model(run.model, state["model"], out_dir)
    set_state_dict(
        run.model,
        run.optimizer,
        model_state_dict=state["model"],
        optim_state_dict=state["optimizer"],
        options=StateDictOptions(full_state_dict=True),
    )
    run.ema.load_state_dict(state["ema"])
    run.step = run.saved_step = int(state["step"])
    run.train_seconds = float(state.get("train_seconds", 0.0))
    run.budget_steps = state.get("budget_steps")
    torch.set_rng_state(state["rng"]["torch"])
    task.load_extra_state(state.get("task", {}))


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
                "train_seconds": run.train_seconds,
                "budget_steps": run.budget_steps,
                "data_position": run.step,
                "rng": {"torch": torch.get_rng_state()},
                "config": config_record,
                "task": task.extra_state(),
            },
        )
    run.saved_step = run.step
    barrier(run.info)


def _metrics_file(out_dir: Path, start_step: int) -> JsonlAppender:
    """metrics.jsonl opened for appending, without rows past ``start_step`` (a resumed run rewrites them)
    and without a torn last row (a kill mid-append)."""
    return JsonlAppender(out_dir / METRICS_NAME, keep=lambda row: _row_step(row) <= start_step)


def _row_step(row: dict) -> float:
    step = row.get("step")
    return step if isinstance(step, int) else float("inf")


def _train_step(run: _Run, task: TrainTask, cfg: TrainConfig) -> tuple[float, float, dict[str, float]]:
    """One optimizer step on this rank's slice of the global batch; returns (mean loss, grad norm, the
    task's named terms of this rank)."""
    info, step = run.info, run.step
    indices = global_batch(step, cfg.batch_size, task.num_samples(), cfg.seed)
    seeds = [mix_seed(cfg.seed, step, j) for j in range(cfg.batch_size)]
    local = slice(info.rank * cfg.batch_size // info.world_size, (info.rank + 1) * cfg.batch_size // info.world_size)
    for group in run.optimizer.param_groups:
        group["lr"] = learning_rate(cfg, step) * group.get("lr_scale", 1.0)  # a run saved before scales: 1
    use_bf16 = cfg.precision == "bf16" or (cfg.precision == "auto" and info.device.type == "cuda")
    with torch.autocast(info.device.type, dtype=torch.bfloat16, enabled=use_bf16):
        loss = task.loss(run.forward, indices[local], seeds[local], info.device)
    loss, terms = loss if isinstance(loss, tuple) else (loss, {})
    loss.backward()
    grad_norm = torch.nn.utils.clip_grad_norm_(
        run.model.parameters(), cfg.grad_clip if cfg.grad_clip > 0 else float("inf")
    )
    mean_loss = loss.detach()
    if info.distributed:
        dist.all_reduce(mean_loss)  # SUM (gloo has no AVG)
        mean_loss /= info.world_size
    grad_norm = grad_norm.full_tensor() if hasattr(grad_norm, "full_tensor") else grad_norm
    mean_loss, grad_norm = float(mean_loss), float(grad_norm)  # every rank: the reduced loss, the global norm
    check_finite_step(step + 1, {"loss": mean_loss, "grad_norm": grad_norm})  # before the update: weights stay good
    run.optimizer.step()
    run.optimizer.zero_grad(set_to_none=True)
    run.ema.update(run.model, step)
    run.step += 1
    terms = {**terms, **task.after_step(run.step)}
    check_finite_step(run.step, terms)  # e.g. a discriminator that diverged: stopped before it is checkpointed
    return mean_loss, grad_norm, terms


class NonFiniteStep(Exception):
    """A training step (``step``, counted from 1 as metrics rows count) whose loss, gradient norm or a logged
    term is NaN or infinite (``values``: the ones that are)."""

    def __init__(self, step: int, values: dict[str, float]):
        super().__init__(f"step {step}: {values}")
        self.step, self.values = step, values


def check_finite_step(step: int, values: dict[str, float]) -> None:
    """Raise :class:`NonFiniteStep` when a value of ``values`` is not finite."""
    bad = {k: v for k, v in values.items() if isinstance(v, float) and not math.isfinite(v)}
    if bad:
        raise NonFiniteStep(step, bad)


def diverged(stop: NonFiniteStep, out_dir: Path, saved_step: int | None) -> DrivewmError:
    """The one-line error of a run stopped at its first non-finite step, saying what ``out_dir`` keeps."""
    kept = (
        f"{out_dir} keeps the last good checkpoint (step {saved_step}), which a rerun resumes"
        if saved_step is not None
        else f"nothing was saved in {out_dir}"
    )
    values = ", ".join(f"{k} {v}" for k, v in stop.values.items())
    return DrivewmError(
        f"train: step {stop.step}: {values} (not finite): the run diverged and stopped; {kept} "
        "(lower train.lr or set train.grad_clip first)"
    )


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
    for folder in (out_dir, out_dir / "samples"):  # a killed run's unfinished checkpoint or sample grid
        remove_dead_temporaries(folder)
    _resume(run, task, out_dir)
    if run.budget_steps is not None:
        cfg = dataclasses.replace(cfg, steps=run.budget_steps)
    start, last = run.step, {}
    stop = cfg.steps if stop_after is None else start + stop_after
    metrics = _metrics_file(out_dir, start) if run.info.is_main else None
    bar = tqdm(desc="train", disable=not run.info.is_main, initial=start, total=cfg.steps)
    busy_s, busy_steps = 0.0, 0  # training time since the last row (checkpoints and samples excluded)
    probe: list[float] = []  # this call's step times while a budgeted run sets its step count
    while run.step < min(cfg.steps, stop):
        tic = time.perf_counter()
        try:
            loss, grad_norm, terms = _train_step(run, task, cfg)
        except NonFiniteStep as stop:
            bar.close()
            if metrics:
                metrics.close()
            raise diverged(stop, out_dir, run.saved_step) from None
        seconds = time.perf_counter() - tic
        busy_s, busy_steps = busy_s + seconds, busy_steps + 1
        run.train_seconds += seconds
        bar.update(1)
        if cfg.budget_minutes and run.budget_steps is None:
            probe.append(seconds)
            if run.step >= min(BUDGET_PROBE_STEPS, cfg.steps):
                run.budget_steps = _rank0(run.info, budget_steps(cfg, run.step, run.train_seconds, probe))
                if run.info.is_main:
                    bar.write(
                        f"train: budget {cfg.budget_minutes:g} min after {run.step} steps in "
                        f"{run.train_seconds:.1f} s -> {run.budget_steps} steps (at most {cfg.steps})"
                    )
                cfg = dataclasses.replace(cfg, steps=run.budget_steps)
                bar.total = cfg.steps
                bar.refresh()
        end = min(cfg.steps, stop)
        if run.step % cfg.log_every == 0 or run.step == end:
            last = {
                "step": run.step,
                "loss": loss,
                "grad_norm": grad_norm,
                "lr": learning_rate(cfg, run.step - 1),
                "tokens_per_s": task.tokens_per_sample() * cfg.batch_size * busy_steps / max(busy_s, 1e-9),
                "train_seconds": run.train_seconds,
                **terms,
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
    bar.close()
    if metrics:
        metrics.close()
    shutdown_distributed()
    return last
