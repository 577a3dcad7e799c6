"""Video2World: a model trained with clean first latent frames keeps them when sampling."""

from __future__ import annotations

import pytest
import torch
from synthetic_latents import make_synthetic_latent_cache

from drivewm.diffusion.data import LatentDataset, denormalize_latents
from drivewm.diffusion.pretrain import pretrain, pretrain_config
from drivewm.diffusion.text2world import Text2World


@pytest.mark.slow
def test_video2world_training_and_sampling_keep_the_condition_frames(tmp_path):
    cache = make_synthetic_latent_cache(tmp_path / "lat", clips_per_condition=2)
    cfg = pretrain_config(
        "debug",
        [
            "model.hidden_dim=32",
            "model.depth=1",
            "model.num_heads=2",
            "text.dim=16",
            "edm.cond_frames=1",
            "train.steps=3",
            "train.batch_size=2",
            "sample_steps=2",
        ],
    )
    pretrain(cfg, cache, None, tmp_path / "v2w")
    model = Text2World.from_pretrained(tmp_path / "v2w")
    assert model.cfg.dit.cond_mask_channel and model.cfg.edm.cond_frames == 1
    data = LatentDataset(cache)
    raw = denormalize_latents(data[0].latents, data.cache.latent_mean, data.cache.latent_std, 0.5)[
        None
    ]  # (1, c, t, h, w)
    out = model.sample_latents([data[0].caption], [0], steps=3, guidance=2.0, cond_latents=raw)
    assert torch.allclose(out[:, :, :1], raw[:, :, :1], atol=1e-5)
    assert not torch.allclose(out[:, :, 1:], raw[:, :, 1:], atol=1e-2)
