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


@pytest.mark.parametrize(
    "argv",
    [
        ["generate", "--prompt", "snow"],
        ["rollout", "--clip", "c.tar", "--trajectory", "left"],
        ["pretrain", "--data", "c"],
        ["posttrain", "--data", "c"],
        ["eval", "c"],
        ["transfer", "c", "--to", "snow"],
        ["transfer-train", "--init", "t", "--data", "c"],
        ["tokenizer", "train", "--data", "c"],
        ["tokenizer", "eval", "--model", "t", "--data", "c"],
        ["tokenizer", "decode", "--model", "t", "--data", "c"],
        ["simulate"],
        ["curate", "log.mcap"],
        ["import-video", "v.mp4", "--calibration", "rig.yaml"],
        ["quickstart"],
        ["worldmodel", "train"],
        ["worldmodel", "export", "run"],
        ["worldmodel", "benchmark", "--heldout", "c"],
    ],
)
@pytest.mark.parametrize("below", [False, True])
def test_an_out_folder_that_is_a_file_is_a_one_line_error(tmp_path, capsys, argv, below):
    """A file at --out (or on the way to it) ended every command that writes a folder in mkdir's
    FileExistsError or NotADirectoryError traceback; now the parser refuses it and the file is kept."""
    (tmp_path / "taken").write_text("keep me")
    out = tmp_path / "taken" / "sub" if below else tmp_path / "taken"
    code = main([*argv, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith(f"{out}: {tmp_path / 'taken'} is a file, not a folder"), err
    assert len(err.splitlines()) == 1 and (tmp_path / "taken").read_text() == "keep me"
