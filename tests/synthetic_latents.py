"""A tiny synthetic latent cache (two captioned conditions) for the tests of the diffusion stages.

Importable from any test (tests/conftest.py puts this folder on ``sys.path``).

Condition ``k`` has latents ``brightness_k`` on the lower half of every channel-0..2 plane and
noise elsewhere, so a model that follows its caption is easy to check without any tokenizer.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import write_latent_clip, write_latent_index
from drivewm.geometry import load_rig

CONDITIONS = {"clear day on a highway": 0.6, "heavy snow on a highway": -0.6}


def make_synthetic_latent_cache(
    out_dir: str | Path,
    clips_per_condition: int = 4,
    latent_shape: tuple[int, int, int, int] = (4, 3, 4, 6),
    fps: float = 10.0,
    seed: int = 0,
) -> Path:
    """Write ``out_dir/index.json`` + one safetensors per clip; latents (1, c, t, h, w) per clip."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rig = load_rig("front1").to_dict()
    gen = torch.Generator().manual_seed(seed)
    c, t, h, w = latent_shape
    frames = 1 + 4 * (t - 1)
    rows = []
    for k, (caption, level) in enumerate(CONDITIONS.items()):
        for i in range(clips_per_condition):
            z = 0.3 * torch.randn(1, c, t, h, w, generator=gen)
            z[:, :3, :, h // 2 :] += level
            key = f"syn{k}_{i:03d}"
            meta = ClipMeta(key, "synthetic", 0, fps, [int(j * 1e9 / fps) for j in range(frames)], rig, caption=caption)
            rows.append(write_latent_clip(out_dir, meta, z, np.tile(np.eye(4), (frames, 1, 1))))
    info = {"path": None, "latent_mean": [0.0] * c, "latent_std": [0.5] * c}
    write_latent_index(out_dir, info, rows)
    return out_dir
