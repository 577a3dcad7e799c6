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
from drivewm.product.release import export_folder
from drivewm.transfer.model import Transfer
from drivewm.transfer.train import RECIPES, init_transfer, train_transfer

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
    assert info["model_type"] == "transfer" and info["parent"] == "../t2w"  # its run's own, wherever the run moves
    assert info["config"]["edm"]["p_mean"] == 0.0 and info["latent"]["latent_shape"] == [4, 2, 4, 6]


def test_a_transfer_folder_is_fine_tuned_as_it_is_and_ships_pointing_at_its_parent(tmp_path) -> None:
    """--init with a transfer folder (say shipped:transfer) starts from its trained weights, not from a
    zero-initialised source branch; the export writes its parent as ../text2world, found beside it."""
    cache, parent = _cache_and_parent(tmp_path)
    cfg = RECIPES.resolve("debug", overrides=["train.steps=2", "train.batch_size=4", "train.checkpoint_every=2"])
    train_transfer(cfg, parent, cache, tmp_path / "first")
    first = load_file(str(tmp_path / "first" / "model.safetensors"))
    start = init_transfer(cfg, tmp_path / "first").net.state_dict()
    assert first["source_encoder.proj.weight"].abs().sum() > 0
    assert all(torch.equal(start[k], first[k]) for k in first)
    train_transfer(cfg, tmp_path / "first", cache, tmp_path / "second")
    second = load_file(str(tmp_path / "second" / "model.safetensors"))
    assert any(not torch.equal(second[k], first[k]) for k in first)  # it trained on
    assert json.loads((tmp_path / "second" / "config.json").read_text())["parent"] == "../t2w"
    assert Transfer.from_pretrained(tmp_path / "second").parent == str(parent.resolve())
    export_folder(parent, tmp_path / "pkg" / "text2world")
    export_folder(tmp_path / "second", tmp_path / "pkg" / "transfer")
    assert json.loads((tmp_path / "pkg" / "transfer" / "config.json").read_text())["parent"] == "../text2world"
    shipped = Transfer.from_pretrained(tmp_path / "pkg" / "transfer")
    assert shipped.parent == str((tmp_path / "pkg" / "text2world").resolve())


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
