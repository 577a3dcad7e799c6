"""Issue 15 item 4: a run killed in the middle of a metrics.jsonl row resumes, and the resumed run
leaves each step's row exactly once."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from synthetic_latents import make_synthetic_latent_cache

from drivewm.diffusion.pretrain import pretrain, pretrain_config

sys.path.insert(0, str(Path(__file__).parent))
from test_loop import TINY  # noqa: E402


@pytest.mark.slow  # trains a tiny DiT twice
def test_resume_after_a_torn_metrics_row(tmp_path: Path):
    latents = make_synthetic_latent_cache(tmp_path / "latents", clips_per_condition=2)
    cfg = pretrain_config("debug", [*TINY, "train.steps=5"])
    out = tmp_path / "run"
    pretrain(cfg, latents, None, out, stop_after=3)  # a checkpoint at step 3
    metrics = out / "metrics.jsonl"
    with metrics.open("a") as f:
        f.write('{"step": 4, "loss": 0.12')  # then killed while appending step 4's row
    pretrain(cfg, latents, None, out)
    lines = metrics.read_text().splitlines()
    assert [json.loads(line)["step"] for line in lines] == [1, 2, 3, 4, 5]
    assert metrics.read_text().endswith("}\n")
