"""The shipped-model recipe: every stage of every profile is a valid drivewm command line."""

from __future__ import annotations

import pytest

from drivewm import resources
from drivewm.cli import build_parser
from drivewm.worldmodel import load_profile, stage_commands


@pytest.mark.parametrize("profile", ["cpu", "gpu"])
def test_every_stage_parses_and_chains_its_outputs(profile, tmp_path):
    p = load_profile(profile)
    stages = stage_commands(p, tmp_path)
    parser = build_parser()
    for name, argv in stages:
        args = parser.parse_args(argv)  # a typo in a profile fails here, not hours into a run
        assert callable(args.func), name
    names = [n for n, _ in stages]
    assert names.index("tokenizer-train") < names.index("encode-train") < names.index("pretrain-image")
    assert names.index("pretrain-image") < names.index("pretrain-video") < names.index("posttrain")
    argv = dict(stages)
    assert argv["pretrain-video"][argv["pretrain-video"].index("--init") + 1] == str(tmp_path / "text2world_image")
    assert argv["posttrain"][argv["posttrain"].index("--init") + 1] == str(tmp_path / "text2world")
    generated = [n for n in names if n.startswith("generate-")]
    assert len(generated) * p.samples_per_benchmark >= 24  # the 24 generated clips at least
    for _, argv in stages:  # packaged recipes, found by name for their stage
        if "--recipe" in argv:
            assert resources.find(f"recipes/{argv[0]}", argv[argv.index("--recipe") + 1], "recipe").is_file()
