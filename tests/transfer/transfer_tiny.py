"""Tiny parent Text2World models for the transfer tests."""

from __future__ import annotations

from pathlib import Path

import torch

from drivewm.cli import main
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


def paired_clips(root: Path, seed: int) -> Path:
    """One simulated highway drive rendered clear and in snow at 160x96, curated with the transfer
    recipe into ``root/clips{seed}`` (one 17-frame clip per condition, same pair id)."""
    logs, clips = root / f"logs{seed}", root / f"clips{seed}"
    sim = ["simulate", "--scenario", "highway", "--duration", "1.7", "--width", "160", "--height", "96"]
    assert main([*sim, "--seed", str(seed), "--conditions", "clear:day,snow:day", "--out", str(logs)]) == 0
    assert main(["curate", str(logs), "--out", str(clips), "--recipe", "transfer"]) == 0
    return clips


def pooled_parent(folder: Path) -> Text2World:
    """The must-hold's parent: a tiny random Text2World model on the pooling stand-in's latents
    (3 x 5 x 12 x 20 for 17-frame 160x96 clips at 8x8), saved to ``folder``."""
    torch.manual_seed(0)
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=3, hidden_dim=64, depth=2, num_heads=4, adaln_lora_dim=8)),
        LatentInfo([3, 5, 12, 20], [0.0] * 3, [0.5] * 3, 10.0, None, {}),
    )
    parent.save_pretrained(folder)
    return parent
