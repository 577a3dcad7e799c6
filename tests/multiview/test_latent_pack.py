"""A latent cache packed to 8 bits (drivewm.clips.latent_pack) comes back as a latent cache that
post-training reads: every value within half a quantisation step, poses and clip metadata exact, a
size limit keeping clips from the whole cache, and the first training loss on it within a hair of
the loss on the original."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from drivewm.clips.latent_pack import main, pack, unpack
from drivewm.clips.latents import LatentCache
from drivewm.multiview.posttrain import posttrain, posttrain_config


@pytest.fixture(scope="module")
def packed(mv_latents, tmp_path_factory):
    root = tmp_path_factory.mktemp("pack")
    report = pack(mv_latents, root / "pack")
    assert unpack(root / "pack", root / "cache") == report["clips"] == report["of"]
    return root, report


def test_values_come_back_within_half_a_step_and_the_rest_exact(mv_latents, packed):
    root, report = packed
    ours, theirs = LatentCache(root / "cache"), LatentCache(mv_latents)
    assert ours.tokenizer == theirs.tokenizer and [r["meta"] for r in ours.rows] == [r["meta"] for r in theirs.rows]
    worst = 0.0
    for i in range(len(theirs)):
        a, b = ours[i], theirs[i]
        span = b.latents.flatten(2).amax(2) - b.latents.flatten(2).amin(2)  # (V, c)
        err = (a.latents - b.latents).abs().flatten(2).amax(2)
        assert (err <= span / 255 / 2 * 1.001 + 1e-7).all()
        assert np.array_equal(a.T_world_from_ego, b.T_world_from_ego)
        worst = max(worst, float((err / theirs.latent_std[None]).max()))
    assert 0 < worst <= report["max_error_in_std"] * 1.001
    float32_bytes = sum(p.stat().st_size for p in mv_latents.glob("*.safetensors"))
    packed_bytes = sum(p.stat().st_size for p in (root / "pack").glob("*.safetensors"))
    assert packed_bytes < 0.4 * float32_bytes  # a quarter, and headers
    assert report["bytes"] == packed_bytes + (root / "pack" / "pack.json").stat().st_size  # all of the pack


def test_a_size_limit_keeps_clips_from_the_whole_cache(mv_latents, tmp_path, capsys):
    full = pack(mv_latents, tmp_path / "all")
    per_clip = full["bytes"] / full["clips"]
    main(["pack", str(mv_latents), str(tmp_path / "some"), "--max-mb", str(per_clip * 3.5 / 1e6)])
    written = sum(p.stat().st_size for p in (tmp_path / "some").iterdir())  # the index counts (it had not)
    written_line = capsys.readouterr().out
    assert written <= per_clip * 3.5 and f"{written / 1e6:.1f} MB" in written_line
    kept = [r["key"] for r in json.loads((tmp_path / "some" / "pack.json").read_text())["clips"]]
    keys = [r["key"] for r in LatentCache(mv_latents).rows]
    assert len(kept) == 3 and kept[0] == keys[0] and keys.index(kept[2]) >= len(keys) // 2  # not the first three
    assert kept == sorted(kept, key=keys.index)  # in the cache's order
    assert f"packed 3 of {len(keys)} clips" in written_line
    with pytest.raises(SystemExit, match="no clip fits"):
        main(["pack", str(mv_latents), str(tmp_path / "none"), "--max-mb", "0.000001"])


def test_post_training_reads_the_unpacked_cache(mv_latents, mv_parent_dir, packed, tmp_path):
    root, _ = packed
    base = ["rig=front3", "train.steps=1", "train.log_every=1", "sample_steps=1"]
    torch.manual_seed(0)
    original = posttrain(posttrain_config("debug", base), mv_parent_dir, mv_latents, tmp_path / "original")
    torch.manual_seed(0)
    restored = posttrain(posttrain_config("debug", base), mv_parent_dir, root / "cache", tmp_path / "restored")
    assert restored["loss"] == pytest.approx(original["loss"], rel=0.02) and restored["loss"] != original["loss"]


def test_parts_are_disjoint_and_unpack_together_to_the_whole_cache(mv_latents, packed, tmp_path, capsys):
    root, _ = packed
    keys = [r["key"] for r in LatentCache(mv_latents).rows]
    parts = [tmp_path / f"part{k}" for k in (1, 2, 3)]
    for k, part in enumerate(parts, 1):
        main(["pack", str(mv_latents), str(part), "--part", f"{k}/3"])
    held = [[r["key"] for r in json.loads((p / "pack.json").read_text())["clips"]] for p in parts]
    assert sorted(sum(held, [])) == sorted(keys) and all(held)  # disjoint (no key twice), all of the cache
    assert held[0][0] == keys[0] and keys.index(held[0][-1]) >= len(keys) // 2  # each part spreads
    main(["unpack", *map(str, parts), str(tmp_path / "cache")])
    merged, whole = LatentCache(tmp_path / "cache"), LatentCache(root / "cache")
    assert merged.tokenizer == whole.tokenizer and len(merged) == len(whole)
    by_key = {whole.rows[i]["key"]: whole[i] for i in range(len(whole))}
    for i in range(len(merged)):
        assert torch.equal(merged[i].latents, by_key[merged.rows[i]["key"]].latents)  # the same quantisation
    with pytest.raises(SystemExit, match="is in .*part1 too"):
        main(["unpack", str(parts[0]), str(root / "pack"), str(tmp_path / "twice")])
    assert not (tmp_path / "twice").exists()  # refused before anything is written
    with pytest.raises(SystemExit):
        main(["pack", str(mv_latents), str(tmp_path / "bad"), "--part", "4/3"])
    assert "1 <= K <= N" in capsys.readouterr().err
