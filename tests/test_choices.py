"""Model folder arguments: ``shipped:KIND`` names the weights drivewm ships, wherever it is installed."""

from __future__ import annotations

import pytest

from drivewm.cli import build_parser, main


@pytest.mark.parametrize(
    "argv, flag, kind",
    [
        (["generate", "--model", "shipped:multiview", "--prompt", "snow", "--out", "g"], "model", "multiview"),
        (["posttrain", "--init", "shipped:multiview", "--data", "c", "--out", "m"], "init", "multiview"),
        (["tokenizer", "encode", "--model", "shipped:tokenizer", "--data", "c"], "model", "tokenizer"),
        (["pretrain", "--tokenizer", "shipped:tokenizer", "--data", "c", "--out", "t"], "tokenizer", "tokenizer"),
    ],
)
def test_shipped_names_resolve_to_the_installed_folders(fake_shipped_weights, argv, flag, kind):
    args = build_parser().parse_args(argv)
    assert getattr(args, flag) == fake_shipped_weights / kind


def test_a_plain_path_stays_a_path(fake_shipped_weights):
    args = build_parser().parse_args(["posttrain", "--init", "runs/mv", "--data", "c", "--out", "m"])
    assert str(args.init) == "runs/mv"


@pytest.mark.parametrize(
    "value, message",
    [("shipped:text2world", "no shipped text2world weights at"), ("shipped:../x", "no shipped model '../x'")],
)
def test_missing_or_unknown_shipped_models_are_one_line_errors(fake_shipped_weights, capsys, value, message):
    code = main(["posttrain", "--init", value, "--data", "c", "--out", "m"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and len(err.splitlines()) == 1
