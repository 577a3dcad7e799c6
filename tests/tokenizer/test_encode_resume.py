"""``drivewm tokenizer encode`` keeps the latent files that the same clip, tokenizer and tiling
wrote (an interrupted encode resumes; a clip folder that grew encodes only its new clips), and
writes again every file whose clip, tokenizer or tiling changed or that is damaged."""

import pytest
import torch

from drivewm.clips.latents import LatentCache
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.latent_cache import encode_clips
from drivewm.tokenizer.tiling import TilingConfig


def _files(cache):
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in cache.glob("*.safetensors")}


@pytest.mark.slow
def test_encode_keeps_what_it_would_write_again(sim_clip_dir, tmp_path):
    clips = tmp_path / "clips"
    clips.mkdir()
    shards = sorted(sim_clip_dir.glob("*.tar"))
    (clips / shards[0].name).symlink_to(shards[0])
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(tmp_path / "tok")

    first = encode_clips(tmp_path / "tok", clips, "c", progress=False)
    cache = clips / "latents" / "c"
    n = first["encoded"]
    assert n >= 1 and first["reused"] == 0
    before = _files(cache)

    # the clip folder grows: only the new shard's clips are encoded, the old files are not touched
    (clips / shards[1].name).symlink_to(shards[1])
    grown = encode_clips(tmp_path / "tok", clips, "c", progress=False)
    assert grown["reused"] == n and grown["encoded"] > n
    after = _files(cache)
    assert all(after[name] == before[name] for name in before)  # same bytes, never rewritten
    every = _files(cache)

    # an encode killed before its index: the rerun keeps every file; a damaged file is written again
    (cache / "index.json").unlink()
    damaged = sorted(every)[0]
    (cache / damaged).write_bytes(every[damaged][0][:100])
    resumed = encode_clips(tmp_path / "tok", clips, "c", progress=False)
    assert resumed["reused"] == grown["encoded"] - 1
    assert (cache / damaged).read_bytes() == every[damaged][0]  # the same latents as the first write
    assert len(LatentCache(cache)) == grown["encoded"]

    # another tiling, or other tokenizer weights under the same cache name: everything is encoded again
    tiled = encode_clips(tmp_path / "tok", clips, "c", TilingConfig(chunk_latent_frames=2), progress=False)
    assert tiled["reused"] == 0
    with torch.no_grad():
        next(iter(tok.parameters())).add_(0.5)
    tok.save_pretrained(tmp_path / "tok")
    retrained = encode_clips(tmp_path / "tok", clips, "c", progress=False)
    assert retrained["reused"] == 0
    assert _files(cache)[damaged][0] != every[damaged][0]
