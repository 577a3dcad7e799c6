"""A run folder moved as a whole (copied back from a GPU machine, renamed) keeps working, and a
fine-tune of the shipped weights keeps finding the shipped tokenizer wherever drivewm is installed:
model folders and latent caches record the folders they depend on by
drivewm.model_folders.portable_reference."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.generate import decode_latents
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
from drivewm.errors import DrivewmError
from drivewm.model_folders import portable_reference, resolve_reference, shipped_model
from drivewm.tokenizer import Tokenizer, preset
from drivewm.transfer.config import TransferConfig
from drivewm.transfer.init import from_text2world
from drivewm.transfer.model import Transfer


def text2world(tokenizer: Path | None, mean: list[float], std: list[float]) -> Text2World:
    torch.manual_seed(0)
    cfg = Text2WorldConfig(DiTConfig(in_channels=16, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8))
    return Text2World(cfg, LatentInfo([16, 2, 4, 6], mean, std, 10.0, str(tokenizer) if tokenizer else None, {}))


def recorded(folder: Path) -> dict:
    return json.loads((folder / "config.json").read_text())


def test_a_recipe_run_moved_as_a_whole_decodes_with_its_own_tokenizer(tmp_path):
    run = tmp_path / "gpu" / "run"
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(run / "tokenizer")
    model = text2world(run / "tokenizer", tok.latent_mean.tolist(), tok.latent_std.tolist())
    model.save_pretrained(run / "text2world")
    from_text2world(model, TransferConfig(), name=str(run / "text2world")).save_pretrained(run / "transfer")
    assert recorded(run / "text2world")["latent"]["tokenizer"] == "../tokenizer"
    assert recorded(run / "transfer")["parent"] == "../text2world"
    latents = torch.randn(1, 16, 2, 4, 6)
    before = decode_latents(latents, Text2World.from_pretrained(run / "text2world").latent.tokenizer)

    moved = tmp_path / "here" / "run"
    shutil.move(run, moved)  # the old folder is gone
    loaded = Text2World.from_pretrained(moved / "text2world")
    assert Path(loaded.latent.tokenizer) == (moved / "tokenizer").resolve()
    np.testing.assert_array_equal(decode_latents(latents, loaded.latent.tokenizer), before)
    transfer = Transfer.from_pretrained(moved / "transfer")
    assert Path(transfer.parent) == (moved / "text2world").resolve()
    assert Path(transfer.latent.tokenizer) == (moved / "tokenizer").resolve()
    transfer.save_pretrained(moved / "transfer_again")  # saved again from the moved run: still relative
    assert recorded(moved / "transfer_again")["latent"]["tokenizer"] == "../tokenizer"


def test_a_fine_tune_of_the_shipped_weights_names_the_shipped_tokenizer_not_its_installed_path(tmp_path):
    shipped = shipped_model("tokenizer")
    stats = json.loads((shipped / "config.json").read_text())
    model = text2world(shipped, stats["latent_mean"], stats["latent_std"])
    model.save_pretrained(tmp_path / "finetuned")
    assert recorded(tmp_path / "finetuned")["latent"]["tokenizer"] == "shipped:tokenizer"
    assert Path(Text2World.from_pretrained(tmp_path / "finetuned").latent.tokenizer) == shipped.resolve()

    # a drivewm whose shipped tokenizer codes other latents: refused, not decoded into noise
    config = recorded(tmp_path / "finetuned")
    config["latent"]["latent_std"] = [s * 1.5 for s in config["latent"]["latent_std"]]
    (tmp_path / "finetuned" / "config.json").write_text(json.dumps(config))
    with pytest.raises(DrivewmError, match="another shipped tokenizer.*latent_std"):
        Text2World.from_pretrained(tmp_path / "finetuned")


def test_a_tokenizer_outside_the_run_keeps_its_absolute_path(tmp_path):
    elsewhere = (tmp_path / "shared" / "tok").resolve()
    assert portable_reference(elsewhere, tmp_path / "run" / "m", tmp_path / "run") == str(elsewhere)
    assert portable_reference(tmp_path / "run" / "tok", tmp_path / "run" / "m", tmp_path / "run") == "../tok"
    assert resolve_reference("../tok", tmp_path / "run" / "m") == (tmp_path / "run" / "tok").resolve()
    assert resolve_reference(str(elsewhere), tmp_path / "x") == elsewhere


@pytest.mark.slow
def test_a_latent_cache_moved_with_its_tokenizer_still_names_it(sim_clip_dir, tmp_path):
    from drivewm.clips.latents import LatentCache
    from drivewm.diffusion.pretrain import encoding_tokenizer
    from drivewm.tokenizer.latent_cache import encode_clips

    run = tmp_path / "gpu" / "run"
    torch.manual_seed(0)
    Tokenizer(preset("debug")).save_pretrained(run / "tokenizer")
    clips = run / "clips" / "train"
    clips.mkdir(parents=True)
    shutil.copy(sorted(sim_clip_dir.glob("*.tar"))[0], clips)
    cache = Path(encode_clips(run / "tokenizer", clips, progress=False)["cache"])
    assert encoding_tokenizer(LatentCache(cache))[0] == (run / "tokenizer").resolve()

    moved = tmp_path / "here" / "run"
    shutil.move(run, moved)
    found, line = encoding_tokenizer(LatentCache(moved / cache.relative_to(run)))
    assert found == (moved / "tokenizer").resolve() and "warning" not in line
