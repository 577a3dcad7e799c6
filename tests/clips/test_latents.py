"""Finding the latent cache next to the clips (the stage-1 place both diffusion stages read from)."""

from __future__ import annotations

import pytest

from drivewm.clips.latents import LatentCache, find_latent_cache
from drivewm.diffusion.synthetic import make_synthetic_latent_cache
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
