"""Issue 15 item 4: a run killed in the middle of a metrics.jsonl row resumes, and the resumed run
leaves each step's row exactly once."""

from __future__ import annotations

import json
from pathlib import Path

from drivewm.diffusion.pretrain import pretrain, pretrain_config
from drivewm.diffusion.synthetic import make_synthetic_latent_cache

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
    "train.steps=5",
]


def test_resume_after_a_torn_metrics_row(tmp_path: Path):
    latents = make_synthetic_latent_cache(tmp_path / "latents", clips_per_condition=2)
    cfg = pretrain_config("debug", TINY)
    out = tmp_path / "run"
    pretrain(cfg, latents, None, out, stop_after=3)  # a checkpoint at step 3
    metrics = out / "metrics.jsonl"
    with metrics.open("a") as f:
        f.write('{"step": 4, "loss": 0.12')  # then killed while appending step 4's row
    pretrain(cfg, latents, None, out)
    lines = metrics.read_text().splitlines()
    assert [json.loads(line)["step"] for line in lines] == [1, 2, 3, 4, 5]
    assert metrics.read_text().endswith("}\n")
