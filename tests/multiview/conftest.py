"""Tiny parent Text2World models for the multi-view tests."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
from drivewm.geometry import load_rig

sys.path.insert(0, str(Path(__file__).parent))  # mv_standin


def tiny_text2world(seed: int = 0, latent_shape=(4, 3, 4, 6)) -> Text2World:
    """A random tiny Text2World model whose zero-initialised layers are perturbed too (as after
    training), so that per-view equality tests compare non-trivial outputs."""
    torch.manual_seed(seed)
    c = latent_shape[0]
    cfg = Text2WorldConfig(DiTConfig(in_channels=c, hidden_dim=48, depth=2, num_heads=4, adaln_lora_dim=8))
    rig = load_rig("front1").to_dict()
    model = Text2World(cfg, LatentInfo(list(latent_shape), [0.1] * c, [0.9] * c, 10.0, None, rig))
    with torch.no_grad():
        for p in model.dit.parameters():
            p.add_(0.05 * torch.randn_like(p))
    return model


@pytest.fixture
def parent() -> Text2World:
    return tiny_text2world()


@pytest.fixture(scope="session")
def mv_latents(sim_clip_dir, tmp_path_factory):
    """The simulated clips coded by the pooling stand-in tokenizer (32x): latents (3, 5, 6, 10) per view."""
    from mv_standin import PoolTokenizer, write_pooled_cache

    return write_pooled_cache(sim_clip_dir, tmp_path_factory.mktemp("mv_latents"), PoolTokenizer(32))


@pytest.fixture(scope="session")
def mv_parent_dir(tmp_path_factory):
    """A tiny random Text2World model folder for those latents (the post-training init)."""
    torch.manual_seed(0)
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=3, hidden_dim=48, depth=2, num_heads=4, adaln_lora_dim=8)),
        LatentInfo([3, 5, 6, 10], [0.0] * 3, [0.5] * 3, 10.0, None, {}),
    )
    out = tmp_path_factory.mktemp("mv_parent")
    parent.save_pretrained(out)
    return out


@pytest.fixture(scope="session")
def mv_with_tokenizer(tmp_path_factory) -> Path:
    """An (untrained) multi-view model whose folder records a real debug tokenizer (4x8x8), front camera
    only."""
    import dataclasses

    from drivewm.multiview.config import MultiViewConfig
    from drivewm.multiview.init import from_text2world
    from drivewm.tokenizer import Tokenizer, preset

    root = tmp_path_factory.mktemp("mv_tok")
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(root / "tok")
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=16, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8)),
        LatentInfo([16, 5, 24, 40], tok.latent_mean.tolist(), tok.latent_std.tolist(), 10.0, str(root / "tok"), {}),
    )
    mv = from_text2world(parent, MultiViewConfig())
    mv.latent = dataclasses.replace(mv.latent, rig=load_rig("nuscenes6").subset(["CAM_FRONT"]).to_dict())
    mv.save_pretrained(root / "mv")
    return root / "mv"
