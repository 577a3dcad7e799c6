"""``drivewm generate`` and ``drivewm rollout``: frozen flags, shortcuts that are ``--set`` of one field."""

from __future__ import annotations

import json

import pytest

from drivewm.cli import build_parser, main

#: Every flag of ``drivewm generate``: a new setting is a GenerateConfig field (``--set``), not a flag.
GENERATE_FLAGS = {
    "-h", "--help", "--model", "--prompt", "--out", "--condition-clip", "--layout", "--scenario", "--steps",
    "--guidance", "--trajectory-guidance", "--sampler", "--seed", "--trajectory", "--device", "--num-samples", "--rig",
    "--recipe", "--set", "--dry-run",
}  # fmt: skip
ROLLOUT_FLAGS = {
    "-h", "--help", "--model", "--clip", "--key", "--out", "--prompt", "--steps", "--guidance",
    "--trajectory-guidance", "--sampler", "--seed", "--trajectory", "--device", "--windows", "--speed",
    "--recipe", "--set", "--dry-run",
}  # fmt: skip


def command(name: str):
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sub.choices[name]


@pytest.mark.parametrize("name, flags", [("generate", GENERATE_FLAGS), ("rollout", ROLLOUT_FLAGS)])
def test_generate_and_rollout_flags_are_frozen_and_help_fits_a_screen(name, flags, monkeypatch):
    parser = command(name)
    assert {flag for action in parser._actions for flag in action.option_strings} == flags
    monkeypatch.setenv("COLUMNS", "80")
    assert len(parser.format_help().splitlines()) <= 60


def test_shortcuts_are_overrides_of_one_field_and_set_wins(capsys, tmp_path):
    argv = ["generate", "--prompt", "snow", "--out", str(tmp_path / "g"), "--steps", "4", "--trajectory", "left"]
    assert main([*argv, "--recipe", "reprojected", "--set", "sampling.steps=6", "--dry-run"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["sampling"]["steps"] == 6 and cfg["trajectory"] == "left"  # --set after the shortcut
    assert cfg["post_processing"] == ["reproject", "reshade", "blend", "stitch"]  # the recipe's
    assert main([*argv, "--dry-run"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    assert cfg["sampling"]["steps"] == 4 and cfg["post_processing"] == []  # plain sampling by default
    assert main(["rollout", "--clip", "c.tar", "--out", str(tmp_path / "r"), "--windows", "3", "--dry-run"]) == 0
    assert json.loads(capsys.readouterr().out)["rollout"]["windows"] == 3


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--set", "post_processing=[warp]"], "post_processing"),
        (["--device", "tpu"], "device"),
        (["--sampler", "ddim"], "sampler"),
        (["--guidance", "nan"], "guidance"),
    ],
)
def test_bad_settings_are_one_line_errors(extra, says, capsys, tmp_path):
    assert main(["generate", "--prompt", "snow", "--out", str(tmp_path / "g"), *extra, "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1 and err.startswith("error:")
