"""The ``drivewm`` command: the parser builds without importing stage code, and every sub-command is there."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import pytest

from drivewm.cli import BROKEN_PIPE_STATUS, build_parser, main

#: Not imported by the parser: each stage imports its libraries in its handler (drivewm/lazy.py).
HEAVY = (
    "torch", "filterpy", "pycolmap", "highway_env", "libsumo", "rerun", "scenedetect", "ray", "transformers",
    "matplotlib", "cv2", "numpy", "drivewm.sim.drives",
)  # fmt: skip
COMMANDS = (
    "simulate", "view", "curate", "import-video", "tokenizer", "pretrain", "generate", "posttrain", "rollout", "eval",
    "quickstart",
)  # fmt: skip


def test_help_imports_no_heavy_module():
    """Building the parser and ``drivewm --help`` load no PyTorch, traffic simulator, COLMAP, Rerun or Ray."""
    code = (
        "import json, sys; from drivewm.cli import build_parser; build_parser().format_help(); "
        f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == []


def test_every_stage_has_its_command():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert set(COMMANDS) <= set(sub.choices)


#: Every count option of the CLI, with the arguments its command needs besides it.
COUNT_OPTIONS = [
    (["curate", "logs", "--out", "o"], "--workers"),
    (["simulate", "--out", "o"], "--workers"),
    (["simulate", "--out", "o"], "--drives"),
    (["eval", "clips", "--out", "o"], "--workers"),
    (["eval", "clips", "--out", "o"], "--threads"),
    (["eval", "clips", "--out", "o"], "--max-clips"),
    (["tokenizer", "eval", "--model", "m", "--data", "d", "--out", "o"], "--max-clips"),
    (["tokenizer", "eval", "--model", "m", "--data", "d", "--out", "o"], "--max-views"),
    (["transfer", "clips", "--to", "snow", "--out", "o"], "--max-clips"),
    (["generate", "--prompt", "x", "--out", "o"], "--num-samples"),
]


def test_tokenizer_threads_take_zero_for_torchs_default_and_refuse_negatives(capsys):
    """``--threads -2`` had ended in PyTorch's set_num_threads traceback."""
    argv = ["tokenizer", "eval", "--model", "m", "--data", "d", "--out", "o", "--threads"]
    assert build_parser().parse_args([*argv, "0"]).threads == 0
    assert main([*argv, "-2"]) == 2
    assert "argument --threads: must be >= 0, got -2" in capsys.readouterr().err


def test_tokenizer_holdout_percent_is_a_percentage_below_100(tmp_path, capsys):
    """``--holdout-percent 150`` had held out every clip without a word; the parser and load_clips refuse it."""
    from drivewm.errors import DrivewmError
    from drivewm.tokenizer.data import load_clips

    argv = ["tokenizer", "eval", "--model", "m", "--data", "d", "--out", "o", "--holdout-percent"]
    assert build_parser().parse_args([*argv, "0"]).holdout_percent == 0
    for bad in ("100", "150", "-5", "10.5"):
        assert main([*argv, bad]) == 2
        err = capsys.readouterr().err
        assert "argument --holdout-percent: " in err and len(err.strip().splitlines()) == 1
    with pytest.raises(DrivewmError, match=r"holdout_percent in \[0, 100\), got 'holdout' and 150"):
        load_clips(tmp_path, "holdout", 150)  # refused before the folder is read
    with pytest.raises(DrivewmError, match="split must be all, train or holdout"):
        load_clips(tmp_path, "test", 10)


@pytest.mark.parametrize(("argv", "option"), COUNT_OPTIONS, ids=lambda v: v if isinstance(v, str) else v[0])
def test_count_options_refuse_zero_negative_and_non_integers(argv, option, capsys):
    """``--workers -3`` had run on one process and ``--max-clips -1`` had scored all clips but the last;
    every count is now refused below 1 by the parser, before any work, with the CLI's one-line error."""
    assert build_parser().parse_args([*argv, option, "3"]).__dict__[option[2:].replace("-", "_")] == 3
    for bad, says in (("0", "must be >= 1, got 0"), ("-1", "must be >= 1, got -1"), ("2.5", "got '2.5'")):
        assert main([*argv, option, bad]) == 2
        err = capsys.readouterr().err
        assert f"argument {option}: " in err and says in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "argv",
    [
        ["generate", "--prompt", "x", "--out", "o"],
        ["rollout", "--clip", "c", "--out", "o"],
        ["transfer", "clips", "--to", "snow", "--out", "o"],
        ["simulate", "--out", "o"],
    ],
    ids=lambda argv: argv[0],
)
def test_seeds_out_of_range_are_refused_by_the_parser(argv, capsys):
    """A seed past 2**63 had ended ``drivewm generate`` in PyTorch's overflow traceback."""
    assert build_parser().parse_args([*argv, "--seed", "2147483647"]).seed == 2**31 - 1
    for bad in ("99999999999999999999999", "-1", "x"):
        assert main([*argv, "--seed", bad]) == 2
        err = capsys.readouterr().err
        assert "argument --seed: " in err and len(err.strip().splitlines()) == 1


def test_a_reader_that_goes_away_ends_the_command_quietly():
    """``drivewm ... | head`` had ended in a BrokenPipeError traceback: now no word on stderr and the
    shell's status for SIGPIPE, as from any command-line tool."""
    read, write = os.pipe()
    os.close(read)  # the reader is gone before the first line
    try:
        argv = ["simulate", "--recipe", "worldmodel", "--dry-run", "--out", "x"]  # 105 lines of resolved config
        proc = subprocess.run([sys.executable, "-m", "drivewm.cli", *argv], stdout=write, stderr=subprocess.PIPE)
    finally:
        os.close(write)
    assert (proc.returncode, proc.stderr) == (BROKEN_PIPE_STATUS, b"")


def sub_commands(parser: argparse.ArgumentParser, prefix: str = "") -> dict[str, argparse.ArgumentParser]:
    """Every leaf command of ``parser`` by its words (``tokenizer train``)."""
    found = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found |= sub_commands(sub, f"{prefix} {name}".strip())
    return found or {prefix: parser}


def help_lines(parser: argparse.ArgumentParser, monkeypatch) -> int:
    """Lines of the command's ``--help`` on an 80-column terminal."""
    monkeypatch.setenv("COLUMNS", "80")
    return len(parser.format_help().splitlines())


#: The flags of ``drivewm tokenizer train``: a preset is ``--preset SIZE --compression TxHxW [--fsq]``,
#: never a compound name; a new flag is a decision, not a side effect.
TOKENIZER_TRAIN_FLAGS = {
    "-h", "--help", "--preset", "--compression", "--fsq", "--no-fsq", "--recipe", "--set", "--dry-run", "--data",
    "--out", "--threads", "--device",
}  # fmt: skip


def test_tokenizer_train_flags_are_frozen_and_its_help_fits_a_screen(monkeypatch):
    train = sub_commands(build_parser())["tokenizer train"]
    assert {flag for action in train._actions for flag in action.option_strings} == TOKENIZER_TRAIN_FLAGS
    presets = next(a for a in train._actions if a.dest == "preset")
    assert list(presets.choices) == ["debug", "tiny", "small", "base"]  # sizes alone
    assert help_lines(train, monkeypatch) <= 60


def test_every_commands_help_fits_a_screen(monkeypatch):
    commands = sub_commands(build_parser())
    assert len(commands) >= 20
    long = {name: n for name, p in commands.items() if (n := help_lines(p, monkeypatch)) > 60}
    assert not long, long
