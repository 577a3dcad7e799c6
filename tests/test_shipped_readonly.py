"""The shipped weights are read-only to drivewm: no ``--out`` lands in the package, however it is spelt, and
every load of a shipped folder checks its files against MANIFEST.json, hashing each file once."""

from __future__ import annotations

import shutil

import pytest

from drivewm import cli, model_folders
from drivewm.atomic import write_text
from drivewm.errors import DrivewmError
from drivewm.model_folders import WEIGHTS_DIR, WEIGHTS_NAME
from drivewm.train.checkpoint import load_model_folder

TOKENIZER = "drivewm-tokenizer"


@pytest.mark.parametrize(
    "argv",
    [
        ["generate", "--prompt", "a road", "--out"],
        ["curate", "LOGS", "--out"],
        ["tokenizer", "train", "--data", "CLIPS", "--out"],
        ["worldmodel", "interpolate", "shipped:multiview", "shipped:multiview", "--alpha", "0.5", "--out"],
    ],
)
def test_an_out_inside_the_shipped_weights_or_empty_is_refused_before_any_work(tmp_path, capsys, argv):
    """The weights folder itself, a new folder in it, a symlink to it, a path through a symlinked parent, and the
    empty path (the current folder) are each one line, exit 2; nothing is written there."""
    (tmp_path / "link").symlink_to(WEIGHTS_DIR / "multiview")
    (tmp_path / "pkg").symlink_to(WEIGHTS_DIR.parent)
    before = sorted((p.name, p.stat().st_mtime_ns) for p in WEIGHTS_DIR.rglob("*"))
    argv = [str(tmp_path) if a in ("LOGS", "CLIPS") else a for a in argv]
    for out in (WEIGHTS_DIR / "multiview", WEIGHTS_DIR / "new", tmp_path / "link", tmp_path / "pkg" / "weights" / "x"):
        assert cli.main([*argv, str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("error: drivewm ") and "lies inside the installed drivewm" in err
    assert cli.main([*argv, ""]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "argument --out: an empty path names no folder" in err
    assert sorted((p.name, p.stat().st_mtime_ns) for p in WEIGHTS_DIR.rglob("*")) == before
    assert not (WEIGHTS_DIR / "new").exists()


@pytest.fixture
def weights_copy(tmp_path, monkeypatch):
    """A copy of the installed weights as the shipped ones, and an empty cache folder for verified files."""
    copy = tmp_path / "weights"
    shutil.copytree(WEIGHTS_DIR, copy)
    monkeypatch.setattr(model_folders, "WEIGHTS_DIR", copy)
    monkeypatch.setenv("DRIVEWM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(model_folders, "_VERIFIED", {})
    return copy


def _hash_counter(monkeypatch) -> list:
    """Count the files hashed from now on."""
    hashed = []
    real = model_folders.file_sha256
    monkeypatch.setattr(model_folders, "file_sha256", lambda path: hashed.append(path.name) or real(path))
    return hashed


def test_a_shipped_file_hashed_once_is_not_hashed_again_in_this_or_another_process(weights_copy, monkeypatch):
    hashed = _hash_counter(monkeypatch)
    load_model_folder("shipped:tokenizer", TOKENIZER)
    assert sorted(hashed) == ["config.json", WEIGHTS_NAME]
    load_model_folder(weights_copy / "tokenizer", TOKENIZER)  # the same folder as a path: the same check
    assert len(hashed) == 2
    monkeypatch.setattr(model_folders, "_VERIFIED", {})  # a new process: the cache file remembers
    load_model_folder("shipped:tokenizer", TOKENIZER)
    assert len(hashed) == 2 and model_folders.verified_cache_path().is_file()
    assert not model_folders.verified_cache_path().is_relative_to(WEIGHTS_DIR.parent)


@pytest.mark.parametrize("damage", ["flip", "grow", "remove", "unlisted"])
def test_a_replaced_or_damaged_shipped_file_is_refused_where_it_is_loaded(weights_copy, monkeypatch, damage):
    """Loading checks the files even after an earlier load cached them: a changed file has a new mtime."""
    load_model_folder("shipped:tokenizer", TOKENIZER)
    target = weights_copy / "tokenizer" / WEIGHTS_NAME
    data = bytearray(target.read_bytes())
    if damage == "flip":  # same size: only the sha256 tells
        data[len(data) // 2] ^= 0xFF
        target.write_bytes(bytes(data))
        message = "sha256 differs from MANIFEST.json"
    elif damage == "grow":
        target.write_bytes(bytes(data) + b"\0")
        message = f"{len(data) + 1} bytes, MANIFEST.json says {len(data)}"
    elif damage == "remove":
        (weights_copy / "tokenizer" / "config.json").unlink()
        message = "not a drivewm model folder|missing, but listed"
    else:
        manifest = weights_copy / "MANIFEST.json"
        manifest.write_text(manifest.read_text().replace('"tokenizer/model.safetensors"', '"tokenizer/other"'))
        message = "model.safetensors: not listed in .*MANIFEST.json"
    with pytest.raises(DrivewmError, match=message):
        load_model_folder("shipped:tokenizer", TOKENIZER)


def test_plain_transfer_refuses_a_replaced_shipped_model_in_one_line(weights_copy, tmp_path, capsys):
    """``drivewm transfer`` without --model loads the shipped transfer model: a replaced file stops it at once."""
    target = weights_copy / "transfer" / WEIGHTS_NAME
    data = bytearray(target.read_bytes())
    data[100] ^= 0x01
    target.write_bytes(bytes(data))
    (tmp_path / "clips").mkdir()
    assert cli.main(["transfer", str(tmp_path / "clips"), "--to", "snow", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {target}: sha256 differs from MANIFEST.json"), err


def test_no_write_enters_the_shipped_weights_by_any_path(tmp_path):
    """Not only --out: every atomic write (a latent cache under a --data folder, say) is refused there, through a
    symlink too, before anything is made; replacing the shipped weights is drivewm.product.release's alone
    (test_shipped_weights.py replaces a copy's)."""
    (tmp_path / "pkg").symlink_to(WEIGHTS_DIR)
    for path in (WEIGHTS_DIR / "tokenizer" / "config.json", WEIGHTS_DIR / "latents" / "x.json", tmp_path / "pkg" / "n"):
        with pytest.raises(DrivewmError, match="lies in drivewm's shipped weights"):
            write_text(path, "{}")
    assert not (WEIGHTS_DIR / "latents").exists() and not (WEIGHTS_DIR / "n").exists()
    tok = ["tokenizer", "encode", "--model", "shipped:tokenizer", "--data", str(tmp_path / "pkg"), "--name", "c"]
    assert cli.main(tok) == 2  # the latent cache folder is not made either
    assert not (WEIGHTS_DIR / "latents").exists()
