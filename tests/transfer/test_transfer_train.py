"""Transfer post-training on the shared loop: resumable exactly, recipes resolve, the CLI dry-runs."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import load_file

from drivewm.cli import main
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.transfer.train import RECIPES, train_transfer

sys.path.insert(0, str(Path(__file__).parent))
from test_data import METAS  # noqa: E402
from transfer_tiny import tiny_text2world  # noqa: E402


def _cache_and_parent(tmp_path: Path) -> tuple[Path, Path]:
    g = torch.Generator().manual_seed(0)
    rows = [
        write_latent_clip(
            tmp_path / "cache", m, torch.randn(3, 4, 2, 4, 6, generator=g), np.tile(np.eye(4), (17, 1, 1))
        )
        for m in METAS
    ]
    write_latent_index(tmp_path / "cache", {"path": None, "latent_mean": [0.0] * 4, "latent_std": [1.0] * 4}, rows)
    tiny_text2world(latent_shape=(4, 2, 4, 6)).save_pretrained(tmp_path / "t2w")
    return tmp_path / "cache", tmp_path / "t2w"


def test_resumed_training_equals_an_uninterrupted_run(tmp_path) -> None:
    cache, parent = _cache_and_parent(tmp_path)
    cfg = RECIPES.resolve("debug", overrides=["train.steps=4", "train.batch_size=4", "train.checkpoint_every=2"])
    train_transfer(cfg, parent, cache, tmp_path / "straight")
    train_transfer(cfg, parent, cache, tmp_path / "resumed", stop_after=2)
    train_transfer(cfg, parent, cache, tmp_path / "resumed")
    a, b = (load_file(str(tmp_path / d / "model.safetensors")) for d in ("straight", "resumed"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert any(k.startswith("source_encoder.") for k in a) and a["source_encoder.proj.weight"].abs().sum() > 0
    info = json.loads((tmp_path / "straight" / "config.json").read_text())
    assert info["model_type"] == "transfer" and info["parent"] == str(parent.resolve())
    assert info["config"]["edm"]["p_mean"] == 0.0 and info["latent"]["latent_shape"] == [4, 2, 4, 6]


def test_transfer_train_dry_run_resolves_presets_recipes_and_overrides(tmp_path, capsys) -> None:
    recipe = tmp_path / "r.yaml"
    recipe.write_text("preset: small\nconfig: {targets: [snow:day]}\noverrides: [train.lr=1e-4]\n")
    argv = ["transfer-train", "--init", "x", "--data", "y", "--out", "z", "--recipe", str(recipe), "--dry-run"]
    assert main([*argv, "--set", "transfer.condition_fields=false"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["preset"] == "small" and cfg["targets"] == ["snow:day"] and cfg["train"]["lr"] == 1e-4
    assert cfg["train"]["steps"] == 10000 and cfg["transfer"]["condition_fields"] is False
    assert (
        main(["transfer-train", "--init", "x", "--data", "y", "--out", "z", "--set", "targets=[hail]", "--dry-run"])
        == 2
    )
