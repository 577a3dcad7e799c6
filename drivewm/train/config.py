"""The shared training loop's settings (no heavy imports: recipes and the CLI read it cheaply)."""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.config import MAX_SEED, above, at_least, in_range, require

Parallel = Literal["auto", "ddp", "fsdp"]

#: Steps a budgeted run (``budget_minutes``) times before it sets its step count; the first two of them
#: (CUDA's kernel selection, compilation) count for nothing, the median of the rest is the step time.
BUDGET_PROBE_STEPS = 10


@dataclasses.dataclass
class TrainConfig:
    """Optimisation and run settings (model and data settings live with the task)."""

    steps: int = 1000
    """Total optimizer steps of the run (a resumed run continues up to this)."""
    budget_minutes: float = 0.0
    """Wall-clock minutes for the run's training steps (0 = no budget). The loop times its first
    ``BUDGET_PROBE_STEPS`` steps, then lowers ``steps`` to what fits the budget (never raises it), so
    one recipe ends its schedule on time on any machine. The count it settles on is saved with every
    checkpoint and a resumed run keeps it. Checkpoints and sample grids are not counted: leave them
    a margin."""
    batch_size: int = 8
    """Global batch: samples per step summed over all ranks (must divide by the world size)."""
    lr: float = 3e-4
    """AdamW peak learning rate."""
    warmup_steps: int = 50
    """Linear learning-rate warm-up from 0."""
    lr_schedule: Literal["constant", "cosine"] = "constant"
    """After warm-up: hold ``lr`` (``constant``), or decay it along a half cosine to
    ``lr * min_lr_ratio`` at the last step (``cosine``; a function of ``steps``, so raising
    ``steps`` on resume stretches the rest of the curve)."""
    min_lr_ratio: float = 0.1
    """Where ``cosine`` ends, as a fraction of ``lr``."""
    weight_decay: float = 0.0
    """AdamW weight decay."""
    betas: list[float] = dataclasses.field(default_factory=lambda: [0.9, 0.99])
    """AdamW betas."""
    grad_clip: float = 1.0
    """Clip the global gradient norm to this (0 = off)."""
    ema_decay: float = 0.999
    """EMA decay of the shipped weights."""
    seed: int = 0
    """Seeds initialisation, data order and every per-sample draw; in [0, 2^31 - 1] as every ``--seed``."""
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
        at_least(self, 0, "warmup_steps", "weight_decay", "grad_clip", "sample_every", "budget_minutes")
        # the steps timed before the count is set must not depend on it: inside the warm-up, or constant
        require(
            not (self.budget_minutes and self.lr_schedule == "cosine" and self.warmup_steps <= BUDGET_PROBE_STEPS),
            "warmup_steps",
            self.warmup_steps,
            f"more than {BUDGET_PROBE_STEPS} with budget_minutes and a cosine schedule (the timed steps' learning "
            "rate must not depend on the step count they set)",
        )
        above(self, 0, "lr")
        in_range(self, "ema_decay", 0, 1, high_open=True)
        in_range(self, "min_lr_ratio", 0, 1)
        in_range(self, "seed", 0, MAX_SEED)  # torch.manual_seed overflowed past 2^64 (a traceback)
        require(
            len(self.betas) == 2 and all(0 <= b < 1 for b in self.betas), "betas", self.betas, "two numbers in [0, 1)"
        )
