"""``drivewm tokenizer encode`` also codes each clip's layout video (its boxes and road lines drawn into
its own cameras) into the latent cache, beside the clip's latents and with the same tokenizer."""

import pytest
import torch

from drivewm.clips.latents import LatentCache
from drivewm.clips.shards import read_clips
from drivewm.tokenizer import Tokenizer, preset
from drivewm.tokenizer.latent_cache import clip_layout_video, encode_clips


@pytest.mark.slow
def test_encode_writes_the_layout_videos_code_beside_the_clips(sim_clip_dir, tmp_path):
    clips = tmp_path / "clips"
    clips.mkdir()
    shard = sorted(sim_clip_dir.glob("*.tar"))[0]
    (clips / shard.name).symlink_to(shard)
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(tmp_path / "tok")
    assert encode_clips(tmp_path / "tok", clips, "c", progress=False)["encoded"] >= 1
    cache = LatentCache(clips / "latents" / "c")
    first = cache[0]
    clip = next(c for c in read_clips(clips) if c.key == first.meta.key)
    assert first.layout_latents is not None and first.layout_latents.shape == first.latents.shape
    with torch.no_grad():
        expected = torch.cat([tok.encode(v[None]) for v in clip_layout_video(clip)])
    torch.testing.assert_close(first.layout_latents, expected, rtol=1e-4, atol=1e-4)
    # the layout's code is not the clip's: a drawn scenario map, not the rendered camera
    assert (first.layout_latents - first.latents).abs().mean() > 0.05
