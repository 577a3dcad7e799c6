"""Non-finite numbers never pass silently (issue 70): a diverging run stops at its first non-finite step with a
one-line error naming it and keeps its last good checkpoint, which resumes; weights holding NaN are refused
where a model folder is loaded; latent caches never take NaN; metrics rows stay strict JSON."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest
import torch
from synthetic_latents import make_synthetic_latent_cache

from drivewm.cli import main
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.train.checkpoint import WEIGHTS_NAME, load_model_folder, load_train_state

sys.path.insert(0, str(Path(__file__).parent))
from test_loop import TINY  # noqa: E402


def tiny_text2world() -> Text2World:
    """A random tiny Text2World model on (4, 3, 4, 6) latents, front camera."""
    torch.manual_seed(0)
    dit = DiTConfig(in_channels=4, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8)
    rig = load_rig("front1").to_dict()
    return Text2World(Text2WorldConfig(dit), LatentInfo([4, 3, 4, 6], [0.0] * 4, [1.0] * 4, 10.0, None, rig))


def _strict_rows(path: Path) -> list[dict]:
    def refuse(token):
        raise AssertionError(f"{path}: {token} is not JSON")

    return [json.loads(line, parse_constant=refuse) for line in path.read_text().splitlines()]


@pytest.mark.slow  # trains a tiny DiT three times
def test_a_diverging_run_stops_at_its_first_non_finite_step_and_its_last_checkpoint_resumes(tmp_path, capsys):
    """A run trained 4 sane steps (checkpoint at 4) goes on at lr 100 and blows up within a few steps. It stops
    at the first step whose loss or gradient norm is not finite, before applying it: exit 2, one line naming
    the step and the checkpoint kept; the model folder holds that checkpoint's finite weights, and
    metrics.jsonl is strict JSON, up to the step before. Resumed at a sane learning rate, it trains on from
    that checkpoint to the end."""
    latents = make_synthetic_latent_cache(tmp_path / "latents", clips_per_condition=2)
    run = tmp_path / "run"
    argv = ["pretrain", "--data", str(latents), "--out", str(run), "--preset", "debug", "--set", "train.sample_every=0"]
    argv += [a for s in TINY for a in ("--set", s)]
    assert main([*argv, "--set", "train.steps=4", "--set", "train.lr=1e-3"]) == 0
    assert main([*argv, "--set", "train.steps=12", "--set", "train.lr=100"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    match = re.fullmatch(
        rf"error: train: step (\d+): (loss|grad_norm) \S+.* \(not finite\): the run diverged and stopped; "
        rf"{re.escape(str(run))} keeps the last good checkpoint \(step 4\), which a rerun resumes .*",
        err,
    )
    assert match, err
    stopped = int(match[1])
    assert load_train_state(run)["step"] == 4 and 4 < stopped <= 12
    load_model_folder(run, "text2world")  # finite, or loading refuses them
    rows = _strict_rows(run / "metrics.jsonl")
    assert [r["step"] for r in rows] == list(range(1, stopped)) and all(r["loss"] is not None for r in rows)

    assert main([*argv, "--set", "train.steps=12", "--set", "train.lr=1e-3"]) == 0
    assert [r["step"] for r in _strict_rows(run / "metrics.jsonl")] == list(range(1, 13))
    assert load_train_state(run)["step"] == 12


def test_weights_holding_nan_are_refused_where_a_model_folder_is_loaded(tmp_path, capsys):
    """A diverged folder had generated all-black clips with exit 0, and ``posttrain --init`` had trained on
    from it, writing bare NaN into metrics.jsonl. Loading refuses it, naming the tensor, whoever loads it."""
    model = tiny_text2world()
    state = {k: v.clone() for k, v in model.dit.state_dict().items()}
    name = sorted(state)[3]
    state[name].view(-1)[0] = float("nan")
    model.save_pretrained(tmp_path / "nan", state)  # a consistent folder: digest and revision match
    with pytest.raises(DrivewmError, match=rf"{WEIGHTS_NAME}: tensor {re.escape(name)} holds NaN or infinity"):
        load_model_folder(tmp_path / "nan", "text2world")
    for argv in (
        ["generate", "--model", str(tmp_path / "nan"), "--prompt", "a road", "--out", str(tmp_path / "gen")],
        ["posttrain", "--init", str(tmp_path / "nan"), "--data", str(tmp_path), "--out", str(tmp_path / "mv")],
    ):
        assert main(argv) == 2
        assert capsys.readouterr().err.splitlines()[-1].startswith(f"error: {tmp_path / 'nan' / WEIGHTS_NAME}: tensor")
    assert not (tmp_path / "gen").exists() and not (tmp_path / "mv" / "metrics.jsonl").exists()


def test_a_latent_cache_never_takes_nan(tmp_path):
    from drivewm.clips.latents import write_latent_clip

    sys.path.insert(0, str(Path(__file__).parents[1] / "clips"))
    from hostile_shards import tiny_clip

    clip = tiny_clip("c0")
    latents = torch.zeros(2, 16, 3, 6, 8)
    latents[1, 4, 2, 0, 0] = float("inf")
    with pytest.raises(DrivewmError, match="clip c0: the tokenizer coded NaN or infinite latents; not cached"):
        write_latent_clip(tmp_path, clip.meta, latents, clip.T_world_from_ego)
    assert list(tmp_path.iterdir()) == []


def test_model_configs_that_are_no_object_or_ask_for_a_huge_latent_are_one_line(tmp_path, capsys):
    """config.json that is JSON but not an object had ended in a traceback; a latent_shape asking for 77 GB
    had ended in an allocation traceback. Both are refused where the folder is read, before any work."""
    tiny_text2world().save_pretrained(tmp_path / "m")
    config = tmp_path / "m" / "config.json"
    info = json.loads(config.read_text())
    for text, message in [
        ("[1, 2, 3]", f"{config}: expected a JSON object, got list"),
        (
            json.dumps({**info, "latent": {**info["latent"], "latent_shape": [4, 1200, 2048, 2048]}}),
            "latent_shape must be <= 67,108,864 values, got [4, 1200, 2048, 2048]",
        ),
    ]:
        config.write_text(text)
        assert (
            main(["generate", "--model", str(tmp_path / "m"), "--prompt", "a road", "--out", str(tmp_path / "g")]) == 2
        )
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("error: ") and message in err, err
