"""The CLI's one place for file-system errors and output-folder locks (drivewm/cli.py, issue 70)."""

from __future__ import annotations

import errno
import os
import tarfile
from pathlib import Path

import pytest

from drivewm import cli
from drivewm.atomic import atomic_path, write_text
from drivewm.errors import DrivewmError


def _command(monkeypatch, func, **defaults):
    """``drivewm eval`` with its function replaced by ``func`` (and extra parser defaults)."""
    parser = cli.build_parser()
    eval_parser = parser._subparsers._group_actions[0].choices["eval"]
    eval_parser.set_defaults(func=func, **defaults)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)


@pytest.mark.parametrize(
    "code, reason",
    [
        (errno.ENOSPC, "No space left on device"),
        (errno.EROFS, "Read-only file system"),
        (errno.EACCES, "Permission denied"),
        (errno.EDQUOT, "Disk quota exceeded"),
    ],
)
def test_a_storage_oserror_is_one_line_naming_the_path(tmp_path, monkeypatch, capsys, code, reason):
    def full(args):
        raise OSError(code, os.strerror(code), str(args.out / "metrics.json"))

    _command(monkeypatch, full)
    assert cli.main(["eval", str(tmp_path), "--out", str(tmp_path / "ev")]) == 2
    assert capsys.readouterr().err == f"error: {tmp_path / 'ev' / 'metrics.json'}: {reason}\n"


def test_any_other_oserror_is_a_bug_and_keeps_its_traceback(tmp_path, monkeypatch):
    def bug(args):
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", "internal.json")

    _command(monkeypatch, bug)
    with pytest.raises(FileNotFoundError):
        cli.main(["eval", str(tmp_path), "--out", str(tmp_path / "ev")])


def test_a_write_that_fails_without_a_name_is_named_by_its_final_path(tmp_path, monkeypatch, capsys):
    """A file object's ``write`` raises without a file name, and a writer in another language (safetensors,
    the MCAP writer) raises its own error type: atomic_path names the final path either way, so the CLI's
    line says where; and nothing is left, under the final name or as a temporary."""

    def rust_writer(args):
        with atomic_path(args.out / "model.safetensors") as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("Error while serializing: I/O error: No space left on device (os error 28)")

    def python_writer(args):
        with atomic_path(args.out / "shard.tar") as tmp, tarfile.open(tmp, "w") as tar:
            tar.fileobj.write(b"x")
            raise OSError(errno.ENOSPC, "No space left on device")  # what tarfile's write raises: no name

    for writer, name in ((rust_writer, "model.safetensors"), (python_writer, "shard.tar")):
        _command(monkeypatch, writer)
        assert cli.main(["eval", str(tmp_path), "--out", str(tmp_path / "ev")]) == 2
        assert capsys.readouterr().err == f"error: {tmp_path / 'ev' / name}: No space left on device\n"
        assert [p.name for p in (tmp_path / "ev").iterdir()] == []


def test_a_declared_output_lock_refuses_a_second_run_and_is_gone_when_nothing_was_written(tmp_path, monkeypatch):
    """A command with ``lock_out`` holds its --out folder's lock: a second run on the folder is refused at once;
    a run that refused its options before any work leaves no folder behind."""
    from drivewm.lock import folder_lock

    seen = []

    def command(args):
        seen.append(sorted(p.name for p in args.out.iterdir()))
        write_text(args.out / "done.txt", "ok")

    _command(monkeypatch, command, lock_out="eval")
    out = tmp_path / "ev"
    with folder_lock(out, "eval"), pytest.raises(DrivewmError, match="another eval run .* is writing this folder"):
        cli._run(cli.build_parser().parse_args(["eval", str(tmp_path), "--out", str(out)]))
    assert cli.main(["eval", str(tmp_path), "--out", str(out)]) == 0
    assert seen == [[".drivewm.lock"]] and (out / "done.txt").read_text() == "ok"

    def refuse(args):
        raise DrivewmError("--speed must be >= 0")

    _command(monkeypatch, refuse, lock_out="eval")
    assert cli.main(["eval", str(tmp_path), "--out", str(tmp_path / "never")]) == 2
    assert not Path(tmp_path / "never").exists()
