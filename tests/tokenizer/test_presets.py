"""A tokenizer preset is a size, a compression and a quantizer: ``--preset tiny --compression 8x16x16 --fsq``."""

from __future__ import annotations

import json

import pytest

from drivewm.cli import main
from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.tokenizer import preset


def dry_run(capsys, tmp_path, *argv: str) -> dict:
    """The resolved run config ``drivewm tokenizer train ... --dry-run`` prints."""
    assert main(["tokenizer", "train", "--data", str(tmp_path), "--out", str(tmp_path / "o"), *argv, "--dry-run"]) == 0
    return json.loads(capsys.readouterr().out)


def test_the_three_flags_build_the_preset_of_that_size_compression_and_quantizer(capsys, tmp_path):
    cfg = dry_run(capsys, tmp_path, "--preset", "tiny", "--compression", "8x16x16", "--fsq")
    assert cfg["model"] == to_dict(preset("tiny", "8x16x16", fsq=True))
    assert (cfg["preset"], cfg["data"]["frames"], cfg["train"]["steps"]) == ("tiny", 17, 20000)
    model = cfg["model"]
    assert (model["temporal_compression"], model["spatial_compression"], model["patch_time"]) == (8, 16, 4)
    assert model["channel_multipliers"] == [1, 2, 2] and model["quantizer"] == "fsq"
    assert model["fsq_levels"] == [8, 8, 8, 5, 5, 5]
    plain = dry_run(capsys, tmp_path)  # the defaults: debug, 4x8x8, continuous
    assert plain["model"] == to_dict(preset("debug")) and plain["data"]["frames"] == 9
    assert (plain["model"]["quantizer"], plain["model"]["latent_channels"]) == ("continuous", 16)


def test_a_recipe_names_the_compression_and_quantizer_and_the_flags_win(capsys, tmp_path):
    recipe = tmp_path / "tok.yaml"
    recipe.write_text("preset: small\ncompression: 1x8x8\nfsq: true\nconfig: {train: {steps: 3}}\n")
    cfg = dry_run(capsys, tmp_path, "--recipe", str(recipe))
    assert cfg["model"] == to_dict(preset("small", "1x8x8", fsq=True)) and cfg["data"]["frames"] == 3
    assert cfg["train"]["steps"] == 3
    flags = dry_run(capsys, tmp_path, "--recipe", str(recipe), "--compression", "8x8x8", "--no-fsq")
    assert flags["model"] == to_dict(preset("small", "8x8x8"))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--preset", "tiny-4x8x8"], "argument --preset: invalid choice: 'tiny-4x8x8'"),
        (["--compression", "4x4x4"], "argument --compression: invalid choice: '4x4x4'"),
    ],
)
def test_compound_names_and_unknown_compressions_are_one_line_errors(capsys, tmp_path, argv, message):
    assert main(["tokenizer", "train", "--data", str(tmp_path), "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_preset_refuses_unknown_sizes_and_compressions_with_the_known_ones():
    with pytest.raises(DrivewmError, match="known: \\['debug', 'tiny', 'small', 'base'\\]"):
        preset("huge")
    with pytest.raises(DrivewmError, match="known: \\['4x8x8', '8x8x8', '8x16x16', '1x8x8'\\]"):
        preset("debug", "2x2x2")
