"""GenerateConfig: plain sampling by default, opt-in post-steps checked and recorded, one recipe form."""

from __future__ import annotations

import pytest

from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.generate.config import POST_STEPS, RECIPES, GenerateConfig
from drivewm.generate.registry import GENERATORS, generator_class


def test_the_packaged_default_recipe_is_the_codes_defaults_and_draws_the_networks_frames():
    cfg = RECIPES.resolve(recipe="default")
    assert to_dict(cfg) == to_dict(GenerateConfig())
    assert cfg.post_processing == [] and cfg.record()["post_processing"] == []
    assert "reproject" not in cfg.record()  # no post-step, no post-step settings in the metadata


def test_post_steps_are_opt_in_by_name_recorded_in_order_and_checked():
    cfg = RECIPES.resolve(recipe="reprojected", overrides=["reproject.steps=3"])
    assert cfg.record()["post_processing"] == list(POST_STEPS)
    assert cfg.record()["reproject"] == {"sigma": 0.1, "steps": 3}
    stitched = RECIPES.resolve(overrides=["post_processing=[stitch]"])
    assert stitched.record()["post_processing"] == ["stitch"] and stitched.post("stitch")
    for bad, says in (
        ("post_processing=[warp]", "post_processing"),
        ("post_processing=[blend]", "with 'reproject'"),  # blend and reshade change the reprojection's input
        ("post_processing=[stitch,stitch]", "without repeats"),
        ("sampling.sampler=ddim", "sampler"),
        ("sampling.steps=0", "steps"),
        ("sampling.guidance_interval=[2,1]", "guidance interval"),
        ("reproject.sigma=0", "reproject.sigma"),
        ("rollout.speed_mps=1e30", "speed_mps"),
        ("sampling.warped_noise=0.5", "unknown key"),
    ):
        with pytest.raises(DrivewmError, match=says):
            RECIPES.resolve(overrides=[bad])


def test_every_registered_generator_class_names_its_model_type():
    for model_type in GENERATORS:
        assert generator_class(model_type).model_type == model_type
    with pytest.raises(DrivewmError, match="known: \\['ar', 'multiview', 'text2world'\\]"):
        generator_class("gan")
