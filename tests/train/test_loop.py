"""The training loop: exact resume, torchrun (2 CPU processes, gloo) == one process, metrics."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file
from synthetic_latents import make_synthetic_latent_cache

from drivewm.diffusion.pretrain import pretrain, pretrain_config
from drivewm.train.loop import global_batch

pytestmark = pytest.mark.slow  # trains models, under torchrun too

REPO = Path(__file__).resolve().parents[2]
TINY = [
    "model.hidden_dim=32",
    "model.depth=2",
    "model.num_heads=2",
    "model.adaln_lora_dim=8",
    "text.dim=16",
    "train.batch_size=4",
    "train.log_every=1",
    "train.checkpoint_every=100",
    "train.warmup_steps=2",
    "sample_steps=2",
]


@pytest.fixture(scope="module")
def latents(tmp_path_factory) -> Path:
    return make_synthetic_latent_cache(tmp_path_factory.mktemp("latents"), clips_per_condition=3)


def _weights(folder: Path) -> dict[str, torch.Tensor]:
    return load_file(str(folder / "model.safetensors"))


def test_global_batch_covers_each_epoch_once():
    first_epoch = global_batch(0, 3, 6, seed=1) + global_batch(1, 3, 6, seed=1)
    assert sorted(first_epoch) == list(range(6)) and global_batch(2, 3, 6, seed=1) != global_batch(2, 3, 6, seed=2)


def test_resumed_run_equals_uninterrupted_run(latents, tmp_path):
    cfg = pretrain_config("debug", TINY + ["train.steps=6"])
    pretrain(cfg, latents, None, tmp_path / "full")
    pretrain(cfg, latents, None, tmp_path / "split", stop_after=3)
    state = torch.load(tmp_path / "split" / "train_state.pt", weights_only=True)
    assert state["step"] == 3 and state["data_position"] == 3
    pretrain(cfg, latents, None, tmp_path / "split")
    full, split = _weights(tmp_path / "full"), _weights(tmp_path / "split")
    assert full.keys() == split.keys()
    assert all(torch.equal(full[k], split[k]) for k in full), "EMA weights differ after resume"
    raw_full = torch.load(tmp_path / "full" / "train_state.pt", weights_only=True)["model"]
    raw_split = torch.load(tmp_path / "split" / "train_state.pt", weights_only=True)["model"]
    assert all(torch.equal(raw_full[k], raw_split[k]) for k in raw_full)
    rows = [json.loads(x) for x in (tmp_path / "split" / "metrics.jsonl").read_text().splitlines()]
    ref = [json.loads(x) for x in (tmp_path / "full" / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == list(range(1, 7)) and [r["loss"] for r in rows] == [r["loss"] for r in ref]
    # It trained: the weights moved from the (zero-initialised) output layer.
    assert full["final.proj.weight"].abs().sum() > 0


@pytest.fixture(scope="module")
def single_process_run(latents, tmp_path_factory) -> dict[str, torch.Tensor]:
    out = tmp_path_factory.mktemp("single")
    pretrain(pretrain_config("debug", TINY + ["train.steps=3"]), latents, None, out)
    return torch.load(out / "train_state.pt", weights_only=True)["model"]


def test_activation_checkpointing_trains_the_same_weights(latents, single_process_run, tmp_path):
    pretrain(
        pretrain_config("debug", TINY + ["train.steps=3", "train.activation_checkpointing=true"]),
        latents,
        None,
        tmp_path,
    )
    ckpt = torch.load(tmp_path / "train_state.pt", weights_only=True)["model"]
    assert max((single_process_run[k] - ckpt[k]).abs().max().item() for k in ckpt) < 1e-6


@pytest.mark.parametrize(
    "parallel, runs",
    [(["train.parallel=ddp"], [3]), (["train.parallel=fsdp", "train.activation_checkpointing=true"], [2, 3])],
    ids=["ddp", "fsdp2-resumed"],
)
def test_torchrun_two_cpu_processes_match_one_process(latents, single_process_run, tmp_path, parallel, runs):
    """DDP in one go; FSDP2 stopped after 2 steps and resumed to 3 (sharded EMA/optimizer reload)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    for steps in runs:
        overrides = TINY + [f"train.steps={steps}", "train.device=cpu"] + parallel
        cmd = [
            sys.executable,
            "-m",
            "torch.distributed.run",
            "--standalone",
            "--nproc_per_node",
            "2",
            "-m",
            "drivewm.cli",
            "pretrain",
            "--data",
            str(latents),
            "--out",
            str(tmp_path / "dist"),
        ] + [a for o in overrides for a in ("--set", o)]
        proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
    single, dist = single_process_run, torch.load(tmp_path / "dist" / "train_state.pt", weights_only=True)["model"]
    assert single.keys() == dist.keys()
    worst = max((single[k] - dist[k]).abs().max().item() for k in single)
    assert worst < 1e-5, f"{parallel[0]} weights differ from one process by {worst}"
    assert single["backbone.final.proj.weight"].abs().max() > 1e-4  # and it did train (not both untouched)
    # The shipped model folder loads into the plain single-device model.
    from drivewm.diffusion.text2world import Text2World

    assert Text2World.from_pretrained(tmp_path / "dist").dit.final.proj.weight.abs().max() > 0


def test_cosine_schedule_warms_up_then_decays_to_the_floor():
    from drivewm.train.config import TrainConfig
    from drivewm.train.loop import learning_rate

    cfg = TrainConfig(steps=101, lr=1.0, warmup_steps=11, lr_schedule="cosine", min_lr_ratio=0.1)
    lrs = [learning_rate(cfg, s) for s in range(cfg.steps)]
    assert lrs[0] == pytest.approx(1 / 11) and lrs[10] == pytest.approx(1.0)
    assert all(a > b for a, b in zip(lrs[10:], lrs[11:]))  # strictly decreasing after warm-up
    assert lrs[55] == pytest.approx(0.55)  # half-way: the mean of peak and floor
    assert lrs[-1] == pytest.approx(0.1)
    constant = TrainConfig(steps=101, lr=1.0, warmup_steps=11)
    assert [learning_rate(constant, s) for s in range(11, 101)] == [1.0] * 90
