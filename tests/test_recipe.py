"""The one recipe form: preset <- recipe config <- recipe overrides <- --set, validated once."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from drivewm.errors import DrivewmError
from drivewm.recipe import PresetAxis, RecipeBook, deep_merge


@dataclasses.dataclass
class Inner:
    steps: int = 10
    lr: float = 1e-3

    def validate(self) -> None:
        if self.steps < 1:
            raise DrivewmError("inner.steps must be >= 1")


@dataclasses.dataclass
class Run:
    preset: str = ""
    width: int = 8
    train: Inner = dataclasses.field(default_factory=Inner)


BOOK = RecipeBook("demo", Run, {"tiny": {"width": 4}, "big": {"width": 64, "train": {"steps": 500}}}, "tiny")


def test_later_sources_win_in_order(tmp_path):
    recipe = tmp_path / "r.yaml"
    recipe.write_text("preset: big\nconfig: {train: {lr: 0.5}}\noverrides: [train.steps=7]\n")
    cfg = BOOK.resolve(None, recipe, ["width=3"])
    assert (cfg.preset, cfg.width, cfg.train.steps, cfg.train.lr) == ("big", 3, 7, 0.5)
    assert BOOK.resolve("tiny", recipe).preset == "tiny"  # the command line's preset beats the recipe's
    assert BOOK.resolve().width == 4 and BOOK.resolve().train.steps == 10


@pytest.mark.parametrize(
    "text",
    [
        "presett: big\n",
        "preset: [1]\n",
        "config: 3\n",
        "overrides: train.steps=1\n",
        "overrides: [train.nope=1]\n",
        "config: {train: {steps: 0}}\n",
        "- a\n",
    ],
)
def test_bad_recipes_are_one_line_errors(tmp_path, text):
    recipe = tmp_path / "r.yaml"
    recipe.write_text(text)
    with pytest.raises(DrivewmError):
        BOOK.resolve(None, recipe)


def test_unknown_preset_lists_the_known_ones():
    with pytest.raises(DrivewmError, match="big"):
        BOOK.resolve("huge")


def test_cli_flags_come_from_the_book():
    parser = argparse.ArgumentParser()
    BOOK.add_arguments(parser)
    args = parser.parse_args(["--preset", "big", "--set", "train.lr=2e-4"])
    assert BOOK.from_args(args).train.lr == 2e-4
    with pytest.raises(SystemExit):
        parser.parse_args(["--preset", "huge"])


def test_deep_merge_copies():
    base = {"a": {"b": 1}}
    merged = deep_merge(base, {"a": {"c": 2}})
    merged["a"]["b"] = 5
    assert base == {"a": {"b": 1}} and merged == {"a": {"b": 5, "c": 2}}


def test_one_preset_shows_no_preset_flag_and_recipes_resolve_by_packaged_name():
    book = RecipeBook("demo", Run, {"default": {}}, "default", recipes="eval")
    parser = argparse.ArgumentParser()
    book.add_arguments(parser)
    assert "--preset" not in parser.format_help() and "packaged: default, quick" in " ".join(
        parser.format_help().split()
    )
    with pytest.raises(SystemExit):
        parser.parse_args(["--preset", "default"])
    assert book.from_args(parser.parse_args(["--set", "width=5"])).width == 5
    assert book.recipe_path("quick").name == "quick.yaml" and book.recipe_path("quick").is_file()
    with pytest.raises(DrivewmError, match="demo recipe 'nope'.*packaged: default, quick"):
        book.recipe_path("nope")


def _wider(preset: str, fields: dict, factor: str) -> dict:
    return {**fields, "width": fields.get("width", 8) * int(factor)}


def _trained(preset: str, fields: dict, on: bool) -> dict:
    return {**fields, "train": {**fields.get("train", {}), "steps": 99}} if on else fields


AXES = (PresetAxis("factor", "1", _wider, "width factor", ("1", "2", "4")), PresetAxis("long", False, _trained, "long"))
AXIS_BOOK = dataclasses.replace(BOOK, axes=AXES)


def test_a_preset_axis_is_a_flag_and_a_recipe_key_after_the_size(tmp_path):
    """--preset stays the size; each axis changes the size's fields, from the command line, else the
    recipe, else its default; the recipe's config and --set still come after."""
    parser = argparse.ArgumentParser()
    AXIS_BOOK.add_arguments(parser)
    args = parser.parse_args(["--preset", "big", "--factor", "4", "--long"])
    cfg = AXIS_BOOK.from_args(args)
    assert (cfg.preset, cfg.width, cfg.train.steps) == ("big", 256, 99)
    assert AXIS_BOOK.from_args(parser.parse_args([])).width == 4  # the defaults change nothing
    recipe = tmp_path / "r.yaml"
    recipe.write_text("preset: big\nfactor: '2'\nlong: true\nconfig: {width: 5}\n")
    assert AXIS_BOOK.resolve(None, recipe).width == 5  # the recipe's config comes after its axes
    recipe.write_text("preset: big\nfactor: '2'\nlong: true\n")
    assert (AXIS_BOOK.resolve(None, recipe).width, AXIS_BOOK.resolve(None, recipe).train.steps) == (128, 99)
    cli = AXIS_BOOK.from_args(parser.parse_args(["--recipe", str(recipe), "--factor", "1", "--no-long"]))
    assert (cli.width, cli.train.steps) == (64, 500)  # the command line beats the recipe
    with pytest.raises(SystemExit):
        parser.parse_args(["--factor", "3"])


@pytest.mark.parametrize(
    ("text", "message"), [("factor: '3'\n", "factor must be one of 1, 2, 4"), ("long: 1\n", "long")]
)
def test_a_bad_axis_value_in_a_recipe_is_a_one_line_error(tmp_path, text, message):
    recipe = tmp_path / "r.yaml"
    recipe.write_text(text)
    with pytest.raises(DrivewmError, match=message):
        AXIS_BOOK.resolve(None, recipe)
    with pytest.raises(DrivewmError, match="unknown recipe key"):
        BOOK.resolve(None, recipe)  # a book without the axis refuses the key
