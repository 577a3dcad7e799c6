"""Tiny FSQ tokenizer folders and FSQ latent caches for the AR tests, made without training anything.

A cache's clips hold token grids whose frames repeat the previous frame at most positions (with a
per-clip random first frame), so a model that reads the previous frame beats the unigram baseline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from drivewm.ar.config import ARConfig
from drivewm.ar.model import ARCondition, ARTransformer
from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.config import to_dict
from drivewm.geometry import load_rig
from drivewm.tokenizer.config import preset
from drivewm.tokenizer.model import Tokenizer


def make_tokenizer(out_dir: Path, fsq: bool = True, seed: int = 0) -> Path:
    """An untrained debug tokenizer folder (FSQ levels [8, 5, 5, 5], or continuous)."""
    torch.manual_seed(seed)
    Tokenizer(preset("debug", fsq=fsq)).save_pretrained(out_dir)
    return out_dir


def make_token_cache(
    clip_dir: Path, tokenizer_dir: Path, clips: int = 6, grid_thw: tuple[int, int, int] = (3, 2, 3), seed: int = 0
) -> tuple[Path, list[torch.Tensor]]:
    """``clip_dir/latents/NAME`` holding ``clips`` one-view clips of FSQ codes; returns it and each clip's
    token grid (t, h, w)."""
    tok = Tokenizer.from_pretrained(tokenizer_dir)
    cache = clip_dir / "latents" / tokenizer_dir.name
    cache.mkdir(parents=True)
    gen = torch.Generator().manual_seed(seed)
    t, h, w = grid_thw
    frames = 1 + tok.config.temporal_compression * (t - 1)
    rows, grids = [], []
    for i in range(clips):
        grid = torch.randint(0, 20, (1, h, w), generator=gen).repeat(t, 1, 1)  # frames repeat the first
        flip = torch.rand(t, h, w, generator=gen) < 0.1
        grid = torch.where(flip, torch.randint(0, 20, (t, h, w), generator=gen), grid)
        codes = tok.quantizer.indices_to_codes(grid[None])  # (1, c, t, h, w)
        meta = ClipMeta(
            f"clip{i:03d}",
            "synthetic",
            0,
            10.0,
            [j * 100_000_000 for j in range(frames)],
            load_rig("front1").to_dict(),
            caption="a highway by day",
        )
        rows.append(write_latent_clip(cache, meta, codes, np.tile(np.eye(4), (frames, 1, 1))))
        grids.append(grid)
    info = {
        "path": str(tokenizer_dir.resolve()),
        "config": to_dict(tok.config),
        "latent_mean": tok.latent_mean.tolist(),
        "latent_std": tok.latent_std.tolist(),
    }
    write_latent_index(cache, info, rows)
    return cache, grids


def tiny_model(seed: int = 0, **fields) -> ARTransformer:
    """A randomly initialised tiny AR transformer (weights spread so its distributions are not flat)."""
    torch.manual_seed(seed)
    cfg = ARConfig(
        **{
            **dict(vocab_size=40, grid_hw=[2, 3], max_frames=3, hidden_dim=32, depth=2, num_heads=2, text_dim=8),
            **fields,
        }
    )
    model = ARTransformer(cfg).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.normal_(0, 0.3)
    return model


def tiny_condition(batch: int = 2, frames: int = 3, seed: int = 0) -> ARCondition:
    """A random condition for :func:`tiny_model` (caption of 4 tokens, the second's last two padded)."""
    gen = torch.Generator().manual_seed(seed)
    mask = torch.tensor([[True, True, True, True], [True, True, False, False]])[:batch]
    return ARCondition(
        torch.randn(batch, 4, 8, generator=gen),
        mask,
        torch.randn(batch, 6, 6, generator=gen),
        torch.randn(batch, frames, 3, generator=gen),
        torch.tensor([10.0, 5.0])[:batch],
    )
