"""Tiny parent Text2World models for the transfer tests."""

from __future__ import annotations

import torch

from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig


def tiny_text2world(seed: int = 0, latent_shape=(4, 3, 4, 6), perturb: float = 0.05) -> Text2World:
    """A random tiny Text2World model whose zero-initialised layers are perturbed too (as after training)."""
    torch.manual_seed(seed)
    c = latent_shape[0]
    cfg = Text2WorldConfig(DiTConfig(in_channels=c, hidden_dim=48, depth=2, num_heads=4, adaln_lora_dim=8))
    model = Text2World(cfg, LatentInfo(list(latent_shape), [0.1] * c, [0.9] * c, 10.0, None, {}))
    with torch.no_grad():
        for p in model.dit.parameters():
            p.add_(perturb * torch.randn_like(p))
    return model
