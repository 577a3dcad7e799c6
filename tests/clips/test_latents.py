"""Finding the latent cache next to the clips (the stage-1 place both diffusion stages read from), and
refusing one whose statistics or latents would turn training NaN."""

from __future__ import annotations

import json

import pytest
from safetensors.torch import load_file, save_file
from synthetic_latents import make_synthetic_latent_cache

from drivewm.clips.latents import LatentCache, find_latent_cache
from drivewm.errors import DrivewmError


def test_cache_found_by_folder_name_or_tokenizer(tmp_path):
    clips = tmp_path / "clips"
    cache = make_synthetic_latent_cache(clips / "latents" / "tok", clips_per_condition=1)
    assert find_latent_cache(cache, None, None) == cache  # the cache folder itself
    assert find_latent_cache(clips, None, "tok") == cache
    assert find_latent_cache(clips, tmp_path / "models" / "tok", None) == cache  # named after the tokenizer folder
    assert len(LatentCache(find_latent_cache(clips, None, "tok"))) == 2


def test_missing_cache_names_the_command_that_makes_it(tmp_path):
    with pytest.raises(DrivewmError, match="name the latent cache"):
        find_latent_cache(tmp_path, None, None)
    with pytest.raises(DrivewmError, match=r"latents/tok: no latent cache; run 'drivewm tokenizer encode"):
        find_latent_cache(tmp_path, tmp_path / "tok", None)


@pytest.mark.parametrize(
    "stats",
    [{"latent_std": [0.0] * 4}, {"latent_std": [0.5]}, {"latent_mean": [float("nan")] * 4}, {"latent_std": None}],
)
def test_cache_statistics_that_training_cannot_divide_by_are_refused(tmp_path, stats):
    """A std of 0, NaN or of the wrong length made every normalised latent inf or NaN (or broke broadcasting
    with a traceback, as a missing one did with a KeyError); the index is refused naming the field."""
    cache = make_synthetic_latent_cache(tmp_path / "c", clips_per_condition=1)
    index = json.loads((cache / "index.json").read_text())
    index["tokenizer"].update(stats)
    (cache / "index.json").write_text(json.dumps(index))
    with pytest.raises(DrivewmError, match=r"index.json: tokenizer.latent_mean and latent_std must be one finite"):
        LatentCache(cache)


def test_a_clip_with_non_finite_latents_is_refused_by_name(tmp_path):
    """One NaN in one cached clip made the loss NaN and every weight of the written model NaN, with exit 0."""
    cache = make_synthetic_latent_cache(tmp_path / "c", clips_per_condition=1)
    path = cache / "syn0_000.safetensors"
    tensors = load_file(str(path))
    tensors["latents"][0, 1, 0, 0, 0] = float("inf")
    save_file(tensors, str(path))
    with pytest.raises(DrivewmError, match=r"syn0_000.safetensors: latents hold NaN or inf"):
        LatentCache(cache)[0]
    assert LatentCache(cache)[1].meta.key == "syn1_000"  # the others still read
