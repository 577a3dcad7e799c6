"""Issue 15 item 1: clip keys, cache names and index rows never make encode or decode write (or read)
outside their folders; a hostile clip is reported and the good clips beside it are still processed."""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

import pytest

from drivewm.cli import main
from drivewm.tokenizer.config import preset
from drivewm.tokenizer.model import Tokenizer

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "clips"))
from hostile_shards import edit_json, files_under, members, write_members, write_shard  # noqa: E402


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """A clip folder whose one shard holds a good clip and two whose KEY.json names a key that is a
    path (relative with '..', absolute), beside a debug tokenizer folder."""
    root = tmp_path_factory.mktemp("hostile")
    good = write_shard(root / "src", "d", ["good", "evil", "abs"])
    items = edit_json(members(good), "evil", lambda m: m.update(key="../../../escaped"))
    items = edit_json(items, "abs", lambda m: m.update(key=str(root / "absolute")))
    write_members(root / "clips" / "d-000000.tar", items)
    Tokenizer(preset("debug")).save_pretrained(root / "tok")
    return root


@pytest.fixture(scope="module")
def encoded(hostile):
    """The hostile folder after one `tokenizer encode` of it: (exit code, files it added, its stdout).
    The decode and cache tests read that cache, so each depends on this, not on test order (a
    worker of pytest -n may run them without the encode test)."""
    before, out = files_under(hostile), io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["tokenizer", "encode", "--model", str(hostile / "tok"), "--data", str(hostile / "clips")])
    return code, files_under(hostile) - before, out.getvalue()


def test_encode_skips_hostile_keys_and_writes_only_inside_the_cache(hostile, encoded):
    code, new, out = encoded
    assert code == 0
    cache = hostile / "clips" / "latents" / "tok"
    assert new == {cache / "good.safetensors", cache / "index.json"}
    assert "skipped evil:" in out and "'../../../escaped'" in out and "skipped abs:" in out
    assert [r["key"] for r in json.loads((cache / "index.json").read_text())["clips"]] == ["good"]


def test_decode_reconstructs_only_the_good_clip(hostile, encoded, capsys):
    out_dir = hostile / "decoded"
    argv = ["tokenizer", "decode", "--model", str(hostile / "tok"), "--data", str(hostile / "clips")]
    before = files_under(hostile)
    assert main([*argv, "--out", str(out_dir)]) == 0
    assert files_under(hostile) - before == {out_dir / "good.CAM_FRONT_LEFT.mp4", out_dir / "good.CAM_FRONT.mp4"}
    assert capsys.readouterr().err.count("skipped:") == 2


def test_hostile_cache_name_and_index_rows_are_refused(hostile, encoded, capsys):
    argv = ["tokenizer", "encode", "--model", str(hostile / "tok"), "--data", str(hostile / "clips")]
    assert main([*argv, "--name", "../../outside"]) == 2
    assert "latent cache name '../../outside'" in capsys.readouterr().err
    assert not (hostile / "outside").exists()
    cache = hostile / "clips" / "latents" / "tok"
    index = json.loads((cache / "index.json").read_text())
    index["clips"][0]["file"] = "../../../tok/model.safetensors"
    bad = hostile / "bad_cache"
    bad.mkdir()
    (bad / "index.json").write_text(json.dumps(index))
    argv = ["tokenizer", "decode", "--model", str(hostile / "tok"), "--latents", str(bad), "--out", str(hostile / "o")]
    assert main(argv) == 2
    assert "file '../../../tok/model.safetensors' or meta key does not match" in capsys.readouterr().err


def test_nothing_decodable_is_a_batch_error_with_one_line_per_clip(hostile, capsys):
    only_bad = hostile / "only_bad"
    write_members(
        only_bad / "x-000000.tar", [m for m in members(hostile / "clips" / "d-000000.tar") if "good" not in m[0]]
    )
    argv = ["tokenizer", "encode", "--model", str(hostile / "tok"), "--data", str(only_bad)]
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    err = err[next(i for i, line in enumerate(err) if line.startswith("error:")) :]  # after the progress bar
    assert err[0].startswith(f"error: {only_bad}: no clip could be encoded (2 failed)")
    assert len(err) == 3 and "clip evil" in err[1] and "clip abs" in err[2]
