"""Curation recipes: the packaged ones resolve, the defaults are spelled out, the CLI takes the one recipe form."""

from __future__ import annotations

import dataclasses
import json

import pytest

from drivewm.cli import main
from drivewm.config import load_yaml, to_dict
from drivewm.curate.config import CURATE_RECIPES, CurateConfig
from drivewm.errors import DrivewmError


def _field_names(cls) -> set[str]:
    """Every field of a config, nested ones as ``section.field``."""
    names = set()
    for f in dataclasses.fields(cls):
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        names |= (
            {f"{f.name}.{n}" for n in _field_names(type(default))} if dataclasses.is_dataclass(default) else {f.name}
        )
    return names


def _keys(d: dict, prefix: str = "") -> set[str]:
    return {k for key, v in d.items() for k in (_keys(v, f"{prefix}{key}.") if isinstance(v, dict) else {prefix + key})}


def test_packaged_recipes_resolve_and_default_spells_out_the_defaults():
    assert CURATE_RECIPES.recipe_names() == [
        "default",
        "fleet",
        "quickstart",
        "test",
        "transfer",
        "video",
        "worldmodel",
    ]
    for name in CURATE_RECIPES.recipe_names():
        assert isinstance(CURATE_RECIPES.resolve(recipe=name), CurateConfig)
    assert to_dict(CURATE_RECIPES.resolve(recipe="default")) == to_dict(CurateConfig())
    written = load_yaml(CURATE_RECIPES.recipe_path("default"))["config"]
    assert _keys(written) == _field_names(CurateConfig)
    assert CURATE_RECIPES.resolve(recipe="video").filters.min_camera_motion_px == 0.5
    worldmodel = CURATE_RECIPES.resolve(recipe="worldmodel")
    assert (worldmodel.resolution, worldmodel.clip_frames, worldmodel.stride_frames) == ([160, 96], 17, 9)
    fleet = CURATE_RECIPES.resolve(recipe="fleet")
    assert (fleet.h264_preset, fleet.h264_threads, fleet.crf) == ("ultrafast", 1, 18)
    transfer = CURATE_RECIPES.resolve(recipe="transfer")  # windows on the same ticks in every condition
    assert (transfer.resolution, transfer.shot_threshold, transfer.filters.dedup_cosine) == ([160, 96], 0.0, 1.0)


def test_cli_dry_run_prints_the_resolved_config(tmp_path, capsys):
    argv = ["curate", str(tmp_path), "--out", str(tmp_path / "clips"), "--recipe", "test"]
    assert main([*argv, "--set", "filters.dedup_cosine=0.99", "--dry-run"]) == 0
    cfg = json.loads(capsys.readouterr().out.splitlines()[0])
    assert cfg["clips_per_shard"] == 8 and cfg["filters"]["dedup_cosine"] == 0.99
    assert not (tmp_path / "clips").exists()


def test_an_old_plain_config_file_is_a_one_line_error_saying_where_fields_go(tmp_path, capsys):
    old = tmp_path / "old.yaml"
    old.write_text("clip_frames: 9\n")
    with pytest.raises(DrivewmError, match="config fields go under 'config:'"):
        CURATE_RECIPES.resolve(recipe=old)
    assert main(["curate", str(tmp_path), "--out", str(tmp_path / "c"), "--recipe", "nope", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "curate recipe 'nope'" in err and "test" in err
