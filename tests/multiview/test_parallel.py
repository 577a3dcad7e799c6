"""Post-training under torchrun (2 CPU processes, gloo) with FSDP2 + activation checkpointing trains
the same weights as one process (drivewm.train.parallelize applied to the multi-view task)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import posttrain, posttrain_config

pytestmark = pytest.mark.slow  # post-trains under torchrun

REPO = Path(__file__).resolve().parents[2]
# Video2World on every step: which steps condition is then the same however the batch is split.
TINY = [
    "train.steps=2",
    "train.batch_size=2",
    "train.checkpoint_every=1000",
    "sample_steps=1",
    "multiview.video2world_prob=1.0",
    "rig=front3",
]


def test_fsdp2_two_processes_match_one_process(mv_latents, mv_parent_dir, tmp_path):
    posttrain(posttrain_config("debug", TINY), mv_parent_dir, mv_latents, tmp_path / "one")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    overrides = TINY + ["train.device=cpu", "train.parallel=fsdp", "train.activation_checkpointing=true"]
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node",
        "2",
        "-m",
        "drivewm.cli",
        "posttrain",
        "--init",
        str(mv_parent_dir),
        "--data",
        str(mv_latents),
        "--out",
        str(tmp_path / "two"),
    ] + [a for o in overrides for a in ("--set", o)]
    proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    one, two = (torch.load(tmp_path / d / "train_state.pt", weights_only=True)["model"] for d in ("one", "two"))
    assert one.keys() == two.keys()
    worst = max((one[k] - two[k]).abs().max().item() for k in one)
    assert worst < 1e-5, f"FSDP2 weights differ from one process by {worst}"
    assert one["camera_encoder.net.2.weight"].abs().max() > 1e-5  # the new parts did train
    assert MultiView.from_pretrained(tmp_path / "two").training_rig.names == [
        "CAM_FRONT_LEFT",
        "CAM_FRONT",
        "CAM_FRONT_RIGHT",
    ]
