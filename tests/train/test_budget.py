"""A run given a wall-clock budget (``train.budget_minutes``) times its first steps, settles on the
step count that fits, and from then on is the run of that many steps: bit-equal weights, task state
and metrics to a run asked for that count outright, interrupted or not. The count is saved with the
checkpoints, so a resume keeps it whatever the new machine's speed."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from drivewm.errors import DrivewmError
from drivewm.train.checkpoint import load_train_state
from drivewm.train.config import BUDGET_PROBE_STEPS, TrainConfig
from drivewm.train.loop import budget_steps, train
from tests.train.test_checkpoint_damage import LinearTask

CFG = TrainConfig(
    steps=10_000, batch_size=4, lr=1e-2, warmup_steps=BUDGET_PROBE_STEPS + 1, lr_schedule="cosine",
    log_every=1, checkpoint_every=100, ema_decay=0.5,
)  # fmt: skip


def _run(out: Path, cfg: TrainConfig, stop_after: int | None = None) -> LinearTask:
    torch.manual_seed(0)
    task = LinearTask()
    train(task, cfg, out, stop_after=stop_after)
    return task


def _rows(out: Path) -> list[dict]:
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in row.items() if k not in ("tokens_per_s", "train_seconds")} for row in rows]


def _same_weights(a: Path, b: Path) -> bool:
    ours, theirs = load_file(str(a / "model.safetensors")), load_file(str(b / "model.safetensors"))
    return ours.keys() == theirs.keys() and all(torch.equal(ours[k], theirs[k]) for k in ours)


def test_the_step_count_fits_the_budget_at_the_median_step_time():
    cfg = dataclasses.replace(CFG, budget_minutes=1.0)
    # 10 steps timed, the first two slow (kernel selection): 0.0125 s a step after them; 0.5 s spent
    times = [0.2, 0.2] + [0.0125] * 8
    assert budget_steps(cfg, 10, 0.5, times) == 10 + int(59.5 / 0.0125)
    assert budget_steps(dataclasses.replace(cfg, steps=500), 10, 0.5, times) == 500  # never more than asked
    assert budget_steps(cfg, 10, 75.0, times) == 10  # the budget is spent: stop where it is
    assert budget_steps(dataclasses.replace(cfg, budget_minutes=float("inf")), 10, 0.5, times) == CFG.steps


def test_a_budgeted_run_is_the_run_of_the_steps_it_settled_on(tmp_path):
    # a budget that ends the run after some hundreds of steps of this task on any machine this runs on
    # (how close the run keeps to its minutes depends on the machine's load, so no test times it)
    budgeted = tmp_path / "budgeted"
    task = _run(budgeted, dataclasses.replace(CFG, budget_minutes=0.01))
    settled = load_train_state(budgeted)["budget_steps"]
    assert BUDGET_PROBE_STEPS < settled < CFG.steps and int(task.steps_seen) == settled

    fixed = tmp_path / "fixed"
    _run(fixed, dataclasses.replace(CFG, steps=settled))
    assert _same_weights(budgeted, fixed) and _rows(budgeted) == _rows(fixed)
    assert _rows(budgeted)[-1]["lr"] == pytest.approx(CFG.lr * CFG.min_lr_ratio)  # the cosine ended on time

    # killed after a checkpoint past the probe, resumed with a budget a slower machine would fill much
    # sooner: the resumed run keeps the settled count and ends as the uninterrupted one did
    resumed = tmp_path / "resumed"
    _run(resumed, dataclasses.replace(CFG, steps=settled, budget_minutes=10.0), stop_after=BUDGET_PROBE_STEPS + 5)
    assert load_train_state(resumed)["budget_steps"] == settled
    task = _run(resumed, dataclasses.replace(CFG, budget_minutes=1e-6))
    assert int(task.steps_seen) == settled
    assert _same_weights(resumed, fixed) and _rows(resumed) == _rows(fixed)


def test_a_cosine_budget_needs_the_timed_steps_inside_the_warm_up():
    with pytest.raises(DrivewmError, match="warmup_steps must be more than 10"):
        dataclasses.replace(CFG, budget_minutes=5.0, warmup_steps=BUDGET_PROBE_STEPS).validate()
    dataclasses.replace(CFG, budget_minutes=5.0, warmup_steps=0, lr_schedule="constant").validate()
    with pytest.raises(DrivewmError, match="budget_minutes must be >= 0"):
        dataclasses.replace(CFG, budget_minutes=-1.0).validate()
